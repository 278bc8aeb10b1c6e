// The World Magnetic Model: the main geomagnetic field from spherical-harmonic (Gauss)
// coefficients in NOAA's .COF format, evaluated at a geodetic point and a date.
//
// Notation (NOAA/BGS, "The US/UK World Magnetic Model for 2025-2030", technical report, sec. 1.2):
//   phi, lambda, h   geodetic latitude, longitude (WGS 84), height above the ellipsoid
//   phi', r          geocentric latitude and radius                                   (eq. 7)
//   g_n^m, h_n^m     Gauss coefficients (nT) at epoch t0, secular variation (nT/yr)   (eq. 9)
//   P_n^m            Schmidt semi-normalised associated Legendre functions of sin(phi') (eq. 4, 5)
//   X', Y', Z'       field north, east, down in the geocentric frame                  (eq. 10)
//   X, Y, Z          the same rotated onto the geodetic vertical by phi' - phi        (eq. 17)
//   D, I, H, F       declination (east of true north), inclination (dip, below the horizontal),
//                    horizontal intensity, total intensity                             (eq. 19)
// Pure computation: the coefficient text is parsed once; evaluation allocates nothing large.
#pragma once

#include <array>
#include <string>

namespace poise {

/// A place on the WGS 84 ellipsoid.
struct GeodeticPoint {
  double lat_deg = 0.0;  ///< geodetic latitude, deg, [-90, 90]
  double lon_deg = 0.0;  ///< longitude, deg east, [-180, 360]
  double alt_m = 0.0;    ///< height above the ellipsoid, m
};

/// The field at a point, geodetic frame (north, east, down), nT; angles in degrees.
struct GeomagneticField {
  double north_nt = 0.0;        ///< X
  double east_nt = 0.0;         ///< Y
  double down_nt = 0.0;         ///< Z
  double horizontal_nt = 0.0;   ///< H
  double total_nt = 0.0;        ///< F
  double declination_deg = 0.0; ///< D, positive east of true north
  double inclination_deg = 0.0; ///< I, the dip: positive below the horizontal
};

/// Highest degree the model supports (WMM: 12).
inline constexpr int kGeomagneticMaxDegree = 12;
/// Below this horizontal intensity the declination is unreliable (NOAA's "blackout zone"), nT.
inline constexpr double kGeomagneticBlackoutHorizontalNt = 2000.0;

class GeomagneticModel {
 public:
  /// Parses .COF text (header "epoch name release-date", then "n m g h g_dot h_dot" lines,
  /// ended by a line of 9s). Throws std::runtime_error "<source>:<line>: ..." on anything else.
  static GeomagneticModel parse(const std::string& text, const std::string& source);
  /// Reads and parses a .COF file (std::runtime_error naming the path when unreadable).
  static GeomagneticModel load(const std::string& path);
  /// The WMM2025 coefficients shipped in config/magnetic/WMM2025.COF, built into the library.
  static const GeomagneticModel& wmm2025();

  /// The field at `p` on `decimal_year`. Throws std::invalid_argument when the point is out of
  /// range or the date lies outside [epoch, epoch + 5) (the model's validity).
  [[nodiscard]] GeomagneticField field(const GeodeticPoint& p, double decimal_year) const;

  [[nodiscard]] double epoch() const { return epoch_; }
  [[nodiscard]] const std::string& name() const { return name_; }
  [[nodiscard]] int max_degree() const { return n_max_; }

 private:
  using Table = std::array<std::array<double, kGeomagneticMaxDegree + 1>, kGeomagneticMaxDegree + 1>;
  double epoch_ = 0.0;
  std::string name_;
  int n_max_ = 0;
  Table g_{}, h_{}, g_dot_{}, h_dot_{};  // [n][m], nT and nT/yr
};

/// "YYYY-MM-DD" (or a decimal year such as "2026.5") as a decimal year: year + (day of year -
/// 1) / days in that year, the convention of NOAA's calculators. Throws std::invalid_argument
/// naming the text otherwise.
double decimal_year_from_date(const std::string& text);

}  // namespace poise
