#include "poise/core/geomagnetic.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>

namespace poise {
namespace detail {
extern const char* const kEmbeddedWmm2025;  // generated from config/magnetic/WMM2025.COF
}  // namespace detail

namespace {

constexpr double kPiG = 3.14159265358979323846;
constexpr double kRad = kPiG / 180.0;
// WGS 84 ellipsoid and the model's reference radius (report sec. 1.2)
constexpr double kWgs84A_km = 6378.137;
constexpr double kWgs84F = 1.0 / 298.257223563;
constexpr double kReferenceRadius_km = 6371.2;
constexpr double kValidityYears = 5.0;
// WMM's stated vertical domain: 1 km below to 850 km above the ellipsoid
constexpr double kMinAlt_m = -1000.0;
constexpr double kMaxAlt_m = 850000.0;

bool only_nines(const std::string& line) {
  bool any = false;
  for (const char c : line) {
    if (c == '9') {
      any = true;
    } else if (c != ' ' && c != '\t' && c != '\r') {
      return false;
    }
  }
  return any;
}

double factorial(int n) {
  double f = 1.0;
  for (int k = 2; k <= n; ++k) {
    f *= k;
  }
  return f;
}

}  // namespace

GeomagneticModel GeomagneticModel::parse(const std::string& text, const std::string& source) {
  GeomagneticModel model;
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  auto fail = [&](const std::string& what) {
    throw std::runtime_error(source + ":" + std::to_string(line_no) + ": " + what);
  };
  bool header = false;
  bool ended = false;
  std::array<std::array<bool, kGeomagneticMaxDegree + 1>, kGeomagneticMaxDegree + 1> seen{};
  while (std::getline(in, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) {
      continue;
    }
    if (!header) {
      std::istringstream h(line);
      if (!(h >> model.epoch_ >> model.name_) || !std::isfinite(model.epoch_) || model.epoch_ < 1900.0 ||
          model.epoch_ > 2200.0) {
        fail("expected the header 'EPOCH NAME DATE' (e.g. '2025.0 WMM-2025 11/13/2024')");
      }
      header = true;
      continue;
    }
    if (only_nines(line)) {
      ended = true;
      break;
    }
    std::istringstream row(line);
    int n = 0;
    int m = 0;
    double g = 0;
    double h = 0;
    double gd = 0;
    double hd = 0;
    if (!(row >> n >> m >> g >> h >> gd >> hd)) {
      fail("expected 'n m g h g_dot h_dot'");
    }
    std::string extra;
    if (row >> extra) {
      fail("unexpected '" + extra + "' after 'n m g h g_dot h_dot'");
    }
    if (n < 1 || n > kGeomagneticMaxDegree || m < 0 || m > n) {
      fail("degree/order (" + std::to_string(n) + ", " + std::to_string(m) + ") outside 1 <= n <= " +
           std::to_string(kGeomagneticMaxDegree) + ", 0 <= m <= n");
    }
    if (!std::isfinite(g) || !std::isfinite(h) || !std::isfinite(gd) || !std::isfinite(hd)) {
      fail("coefficients must be finite numbers");
    }
    if (seen[n][m]) {
      fail("coefficient (" + std::to_string(n) + ", " + std::to_string(m) + ") given twice");
    }
    seen[n][m] = true;
    model.g_[n][m] = g;
    model.h_[n][m] = h;
    model.g_dot_[n][m] = gd;
    model.h_dot_[n][m] = hd;
    model.n_max_ = std::max(model.n_max_, n);
  }
  if (!header) {
    fail("empty: no coefficient header");
  }
  if (!ended) {
    fail("no end line (a line of 9s) after the coefficients");
  }
  for (int n = 1; n <= model.n_max_; ++n) {
    for (int m = 0; m <= n; ++m) {
      if (!seen[n][m]) {
        fail("coefficient (" + std::to_string(n) + ", " + std::to_string(m) + ") is missing");
      }
    }
  }
  return model;
}

GeomagneticModel GeomagneticModel::load(const std::string& path) {
  std::ifstream f(path);
  if (!f) {
    throw std::runtime_error(path + ": cannot open the magnetic model (a .COF file)");
  }
  std::ostringstream text;
  text << f.rdbuf();
  return parse(text.str(), path);
}

const GeomagneticModel& GeomagneticModel::wmm2025() {
  static const GeomagneticModel model = parse(detail::kEmbeddedWmm2025, "config/magnetic/WMM2025.COF");
  return model;
}

GeomagneticField GeomagneticModel::field(const GeodeticPoint& p, double decimal_year) const {
  if (!(std::abs(p.lat_deg) <= 90.0)) {
    throw std::invalid_argument("latitude must be in [-90, 90] deg");
  }
  if (!(p.lon_deg >= -180.0 && p.lon_deg <= 360.0)) {
    throw std::invalid_argument("longitude must be in [-180, 360] deg");
  }
  if (!(p.alt_m >= kMinAlt_m && p.alt_m <= kMaxAlt_m)) {
    throw std::invalid_argument("altitude must be in [-1000, 850000] m above the WGS 84 ellipsoid");
  }
  if (!(decimal_year >= epoch_ && decimal_year < epoch_ + kValidityYears)) {
    std::ostringstream os;
    // three decimals: 2024-12-31 is 2024.997, which the default precision printed as "2025" (issue 33)
    std::ostringstream date;
    date << std::fixed << std::setprecision(3) << decimal_year;
    os << "date " << date.str() << " is outside " << name_ << "'s validity [" << epoch_ << ", "
       << epoch_ + kValidityYears << ")";
    throw std::invalid_argument(os.str());
  }
  const double dt_yr = decimal_year - epoch_;

  // geodetic -> geocentric (report eq. 7)
  const double lat = p.lat_deg * kRad;
  const double lon = p.lon_deg * kRad;
  const double h_km = p.alt_m * 1e-3;
  const double e2 = kWgs84F * (2.0 - kWgs84F);
  const double sin_lat = std::sin(lat);
  const double cos_lat = std::cos(lat);
  const double rc = kWgs84A_km / std::sqrt(1.0 - e2 * sin_lat * sin_lat);  // prime vertical radius
  const double px = (rc + h_km) * cos_lat;
  const double pz = (rc * (1.0 - e2) + h_km) * sin_lat;
  const double r = std::hypot(px, pz);
  const double lat_c = std::asin(pz / r);
  const double x = std::sin(lat_c);
  const double c = std::cos(lat_c);

  // Associated Legendre functions of x = sin(phi') without normalisation (no Condon-Shortley
  // phase), their derivatives d/dphi', and P / cos(phi') for m >= 1 (finite at the poles, where
  // the east component's 1/cos(phi') would otherwise divide by zero). Recursions in n at fixed m:
  //   P_m^m = (2m-1) cos P_{m-1}^{m-1},   P_{m+1}^m = (2m+1) x P_m^m,
  //   (n-m) P_n^m = (2n-1) x P_{n-1}^m - (n+m-1) P_{n-2}^m; their derivatives by the chain rule.
  Table pl{};
  Table dpl{};
  Table pc{};
  pl[0][0] = 1.0;
  for (int m = 0; m <= n_max_; ++m) {
    if (m > 0) {
      pl[m][m] = (2 * m - 1) * c * pl[m - 1][m - 1];
      dpl[m][m] = (2 * m - 1) * (c * dpl[m - 1][m - 1] - x * pl[m - 1][m - 1]);
      pc[m][m] = (2 * m - 1) * pl[m - 1][m - 1];
    }
    for (int n = m + 1; n <= n_max_; ++n) {
      const double a = 2 * n - 1;
      const double b = (n >= m + 2) ? (n + m - 1) : 0.0;
      const double pl2 = (n >= m + 2) ? pl[n - 2][m] : 0.0;
      const double dpl2 = (n >= m + 2) ? dpl[n - 2][m] : 0.0;
      const double pc2 = (n >= m + 2) ? pc[n - 2][m] : 0.0;
      pl[n][m] = (a * x * pl[n - 1][m] - b * pl2) / (n - m);
      dpl[n][m] = (a * (c * pl[n - 1][m] + x * dpl[n - 1][m]) - b * dpl2) / (n - m);
      pc[n][m] = (a * x * pc[n - 1][m] - b * pc2) / (n - m);
    }
  }

  // Spherical-harmonic synthesis (report eq. 10), Schmidt semi-normalisation
  // S_n^m = sqrt((2 - delta_m0) (n-m)! / (n+m)!) (eq. 4).
  double xp = 0.0;
  double yp = 0.0;
  double zp = 0.0;
  const double ratio = kReferenceRadius_km / r;
  double k = ratio * ratio;
  for (int n = 1; n <= n_max_; ++n) {
    k *= ratio;  // (a / r)^(n+2)
    for (int m = 0; m <= n; ++m) {
      const double s = std::sqrt((m == 0 ? 1.0 : 2.0) * factorial(n - m) / factorial(n + m));
      const double g = g_[n][m] + dt_yr * g_dot_[n][m];
      const double h = h_[n][m] + dt_yr * h_dot_[n][m];
      const double cm = std::cos(m * lon);
      const double sm = std::sin(m * lon);
      const double a = g * cm + h * sm;
      xp -= k * a * s * dpl[n][m];
      yp += k * m * (g * sm - h * cm) * s * pc[n][m];
      zp -= (n + 1) * k * a * s * pl[n][m];
    }
  }

  // geocentric -> geodetic vertical (eq. 17)
  const double psi = lat_c - lat;
  GeomagneticField f;
  f.north_nt = xp * std::cos(psi) - zp * std::sin(psi);
  f.east_nt = yp;
  f.down_nt = xp * std::sin(psi) + zp * std::cos(psi);
  f.horizontal_nt = std::hypot(f.north_nt, f.east_nt);
  f.total_nt = std::hypot(f.horizontal_nt, f.down_nt);
  f.declination_deg = std::atan2(f.east_nt, f.north_nt) / kRad;
  f.inclination_deg = std::atan2(f.down_nt, f.horizontal_nt) / kRad;
  return f;
}

double decimal_year_from_date(const std::string& text) {
  const auto bad = [&text]() {
    return std::invalid_argument("date '" + text + "' is neither YYYY-MM-DD nor a decimal year (e.g. 2026.5)");
  };
  int y = 0;
  int mo = 0;
  int d = 0;
  char dash1 = 0;
  char dash2 = 0;
  std::istringstream in(text);
  if (text.size() == 10 && (in >> y >> dash1 >> mo >> dash2 >> d) && dash1 == '-' && dash2 == '-' &&
      in.peek() == std::char_traits<char>::eof()) {
    const bool leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    static constexpr int kDays[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
    if (y < 1900 || y > 2200 || mo < 1 || mo > 12 || d < 1 || d > kDays[mo - 1] + ((mo == 2 && leap) ? 1 : 0)) {
      throw bad();
    }
    int day_of_year = d;
    for (int i = 0; i < mo - 1; ++i) {
      day_of_year += kDays[i] + ((i == 1 && leap) ? 1 : 0);
    }
    return y + (day_of_year - 1) / (leap ? 366.0 : 365.0);
  }
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    throw bad();
  }
  if (used != text.size() || !std::isfinite(v) || v < 1900.0 || v > 2200.0) {
    throw bad();
  }
  return v;
}

}  // namespace poise
