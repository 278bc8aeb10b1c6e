// True north for attitude outputs. The filters estimate heading against the horizontal
// magnetic field, so their world frame is magnetic ENU (y = magnetic north). Given the magnetic
// declination D (magnetic north's angle east of true north), q_true_magnetic = Rz(-D) turns
// that frame into true ENU (y = true north): yaw_true = yaw_magnetic - D (yaw counter-clockwise
// from east, docs/CONVENTIONS.md). D is configured in degrees or computed from a location and a
// date with the World Magnetic Model (poise/core/geomagnetic.h); the model's field magnitude and
// dip at that location can also seed a filter's start-up field reference.
// Each output says its frame: frame id "enu_magnetic" without a declination, "enu_true" with one.
#pragma once

#include "poise/core/geomagnetic.h"
#include "poise/core/types.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>
#include <string>

namespace poise {

/// The frame id of an output in magnetic ENU (no declination configured).
inline constexpr const char* kFrameEnuMagnetic = "enu_magnetic";
/// The frame id of an output in true ENU (a declination configured, possibly 0).
inline constexpr const char* kFrameEnuTrue = "enu_true";

/// How north is configured. Either declination_deg, or a location (+ date), or neither
/// (magnetic ENU).
struct NorthParams {
  double declination_deg = std::nan("");  ///< D, deg east of true north; NaN = not given
  bool has_location = false;              ///< location given: D (and the field) from the model
  GeodeticPoint location;                 ///< WGS 84 latitude, longitude, height above the ellipsoid
  std::string date;                       ///< YYYY-MM-DD or decimal year; empty = the caller's today
  std::string model_file;                 ///< a .COF file; empty = the built-in WMM2025
  bool seed_field = true;                 ///< location given: seed the field reference with |B| and dip

  [[nodiscard]] bool configured() const { return has_location || !std::isnan(declination_deg); }
};

/// North as resolved for one run.
struct NorthReference {
  bool true_north = false;       ///< a declination is applied (output in true ENU)
  double declination_rad = 0.0;  ///< D, rad east
  /// From the model at the location (NaN without a location or when seeding is off):
  double field_ut = std::nan("");  ///< |B|, uT
  double dip_deg = std::nan("");   ///< inclination, deg below the horizontal
  std::string source;              ///< how D was obtained, for logs ("configured", "WMM-2025 at ...")

  [[nodiscard]] const char* frame_id() const { return true_north ? kFrameEnuTrue : kFrameEnuMagnetic; }
  /// Rz(-D): magnetic ENU -> true ENU (identity without a declination).
  [[nodiscard]] Eigen::Quaterniond q_true_magnetic() const {
    return Eigen::Quaterniond(Eigen::AngleAxisd(-declination_rad, Eigen::Vector3d::UnitZ()));
  }
  /// q_world_body from magnetic to true ENU (returned unchanged, bit for bit, without a declination).
  [[nodiscard]] Eigen::Quaterniond to_true(const Eigen::Quaterniond& q_magnetic_body) const {
    return true_north ? (q_true_magnetic() * q_magnetic_body).normalized() : q_magnetic_body;
  }
  /// A world vector from magnetic to true ENU.
  [[nodiscard]] Eigen::Vector3d to_true(const Eigen::Vector3d& v_magnetic) const {
    return true_north ? Eigen::Vector3d(q_true_magnetic() * v_magnetic) : v_magnetic;
  }
  /// A world covariance (3x3 block) from magnetic to true ENU: R P R^T.
  [[nodiscard]] Eigen::Matrix3d to_true(const Eigen::Matrix3d& p_magnetic) const {
    if (!true_north) {
      return p_magnetic;
    }
    const Eigen::Matrix3d r = q_true_magnetic().toRotationMatrix();
    return r * p_magnetic * r.transpose();
  }
  /// The inverses, for inputs given in true ENU (e.g. a tag map laid out on true north).
  [[nodiscard]] Eigen::Quaterniond to_magnetic(const Eigen::Quaterniond& q_true_body) const {
    return true_north ? (q_true_magnetic().conjugate() * q_true_body).normalized() : q_true_body;
  }
  [[nodiscard]] Eigen::Vector3d to_magnetic(const Eigen::Vector3d& v_true) const {
    return true_north ? Eigen::Vector3d(q_true_magnetic().conjugate() * v_true) : v_true;
  }
  /// A world covariance made of 3-blocks (e.g. [position | rotation], 6x6; [p | v | theta],
  /// 9x9) into true ENU (`inverse`: into magnetic ENU): B P B^T with B = diag(R, R, ...).
  template <int N>
  [[nodiscard]] Eigen::Matrix<double, N, N> rotate_covariance(const Eigen::Matrix<double, N, N>& p,
                                                              bool inverse) const {
    static_assert(N % 3 == 0, "3-blocks");
    if (!true_north) {
      return p;
    }
    const Eigen::Matrix3d r = inverse ? Eigen::Matrix3d(q_true_magnetic().conjugate().toRotationMatrix())
                                      : Eigen::Matrix3d(q_true_magnetic().toRotationMatrix());
    Eigen::Matrix<double, N, N> b = Eigen::Matrix<double, N, N>::Zero();
    for (int i = 0; i < N; i += 3) {
      b.template block<3, 3>(i, i) = r;
    }
    return b * p * b.transpose();
  }
  /// A camera pose given in true ENU (a tag map laid out on true north) into magnetic ENU, the
  /// frame the filters work in.
  [[nodiscard]] CameraPoseMeasurement to_magnetic(const CameraPoseMeasurement& m) const {
    if (!true_north) {
      return m;
    }
    CameraPoseMeasurement out = m;
    out.p_world_camera_m = to_magnetic(m.p_world_camera_m);
    out.q_world_camera = to_magnetic(m.q_world_camera);
    out.covariance = rotate_covariance<6>(m.covariance, true);
    return out;
  }
};

/// Resolves `p`: declination_deg as given, or the model's D at the location on `p.date` (or
/// `today` when p.date is empty; YYYY-MM-DD). Throws std::invalid_argument with a message saying
/// what to fix: both forms given, D outside [-180, 180], an unreadable model, a date outside the
/// model's validity, a location in the polar "blackout zone" (H < 2000 nT, where D is unreliable:
/// give declination_deg there).
NorthReference resolve_north(const NorthParams& p, const std::string& today);

/// Writes a field (|B| uT, dip deg; NaN = none) into a filter's start-up reference where the
/// filter's own value is not configured (NaN).
inline void seed_field_reference(double field_ut, double dip_deg_in, double& field_magnitude_ut, double& dip_deg) {
  if (std::isnan(field_magnitude_ut) && !std::isnan(field_ut)) {
    field_magnitude_ut = field_ut;
  }
  if (std::isnan(dip_deg) && !std::isnan(dip_deg_in)) {
    dip_deg = dip_deg_in;
  }
}

/// Writes the model's field into a filter's start-up reference (|B| uT, dip deg) when `north`
/// carries one and the filter's own value is not configured (NaN).
inline void seed_field_reference(const NorthReference& north, double& field_magnitude_ut, double& dip_deg) {
  seed_field_reference(north.field_ut, north.dip_deg, field_magnitude_ut, dip_deg);
}

}  // namespace poise
