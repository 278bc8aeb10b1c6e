#include "poise/ros2_bridge/convert.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cctype>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace poise::ros2 {
namespace {

constexpr int64_t kNsPerS = 1000000000LL;

std_msgs::msg::dds_::Header_ header(int64_t stamp_ns, const std::string& frame, int64_t offset_ns) {
  std_msgs::msg::dds_::Header_ h;
  // Out of ROS's int32 range: stamp 0 here; the bridge checks to_ros_time() before it writes
  // (such a message is counted <what>_bad_stamp, never sent).
  h.stamp(to_ros_time(stamp_ns, offset_ns).value_or(ros_time::Time_{}));
  h.frame_id(frame);
  return h;
}

ros_geo::Vector3_ vec(double x, double y, double z) {
  ros_geo::Vector3_ v;
  v.x(x);
  v.y(y);
  v.z(z);
  return v;
}
ros_geo::Vector3_ vec(const msg::Vector3& in) { return vec(in.x(), in.y(), in.z()); }

ros_geo::Quaternion_ quat(const msg::Quaternion& q) {
  ros_geo::Quaternion_ out;
  out.x(q.x());
  out.y(q.y());
  out.z(q.z());
  out.w(q.w());
  return out;
}

/// REP 145: an absent part has -1 in element 0 (the rest 0); a present one with unknown
/// covariance is all zeros.
template <std::size_t N>
std::array<double, N> presence(bool present) {
  std::array<double, N> c{};
  if (!present) {
    c[0] = -1.0;
  }
  return c;
}

template <std::size_t N>
bool finite(const std::array<double, N>& a) {
  for (double v : a) {
    if (!std::isfinite(v)) {
      return false;
    }
  }
  return true;
}
bool finite(const ros_geo::Vector3_& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}
bool finite(const ros_geo::Point_& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}
bool finite(const ros_geo::Quaternion_& q) {
  return std::isfinite(q.x()) && std::isfinite(q.y()) && std::isfinite(q.z()) && std::isfinite(q.w());
}
bool finite(const ros_geo::PoseWithCovariance_& p) {
  return finite(p.pose().position()) && finite(p.pose().orientation()) && finite(p.covariance());
}

Eigen::Quaterniond eigen(const msg::Quaternion& q) { return {q.w(), q.x(), q.y(), q.z()}; }

}  // namespace

std::optional<ros_time::Time_> to_ros_time(int64_t stamp_ns, int64_t offset_ns) {
  // Both are within +-2^63; their sum may not be: refuse rather than wrap.
  if ((offset_ns > 0 && stamp_ns > std::numeric_limits<int64_t>::max() - offset_ns) ||
      (offset_ns < 0 && stamp_ns < std::numeric_limits<int64_t>::min() - offset_ns)) {
    return std::nullopt;
  }
  const int64_t t = stamp_ns + offset_ns;
  int64_t sec = t / kNsPerS;
  int64_t nsec = t % kNsPerS;
  if (nsec < 0) {
    nsec += kNsPerS;
    sec -= 1;
  }
  if (sec < std::numeric_limits<int32_t>::min() || sec > std::numeric_limits<int32_t>::max()) {
    return std::nullopt;
  }
  ros_time::Time_ out;
  out.sec(static_cast<int32_t>(sec));
  out.nanosec(static_cast<uint32_t>(nsec));
  return out;
}

std::optional<int64_t> from_ros_time(const ros_time::Time_& t, int64_t offset_ns) {
  if (t.sec() < 0 || t.nanosec() >= static_cast<uint32_t>(kNsPerS)) {
    return std::nullopt;
  }
  // sec < 2^31, so the sum is below 2^62 and the offset (|offset| < 2^62 by the caller) fits.
  return static_cast<int64_t>(t.sec()) * kNsPerS + static_cast<int64_t>(t.nanosec()) - offset_ns;
}

ros_sensor::Imu_ attitude_to_imu(const msg::AttitudeEstimate& estimate, const msg::ImuSample* sample,
                                 const Frames& frames, int64_t offset_ns) {
  ros_sensor::Imu_ out;
  out.header(header(estimate.header().stamp_ns(), frames.body, offset_ns));
  out.orientation(quat(estimate.q_world_body()));
  out.orientation_covariance(estimate.attitude_covariance());
  const bool gyro = sample != nullptr && sample->valid().gyro();
  const bool accel = sample != nullptr && sample->valid().accel();
  out.angular_velocity(gyro ? vec(sample->gyro_rps()) : vec(0, 0, 0));
  out.angular_velocity_covariance(presence<9>(gyro));
  out.linear_acceleration(accel ? vec(sample->accel_mps2()) : vec(0, 0, 0));
  out.linear_acceleration_covariance(presence<9>(accel));
  return out;
}

std::string heading_status_word(msg::HeadingStatus status) {
  switch (status) {
    case msg::HEADING_NO_REFERENCE: return "no_reference";
    case msg::HEADING_VERIFIED: return "verified";
    case msg::HEADING_UNVERIFIED: return "unverified";
  }
  return "unknown";
}

ros_diag::DiagnosticArray_ heading_status_to_diagnostics(const msg::AttitudeEstimate& estimate,
                                                         const std::string& filter, const Frames& frames,
                                                         int64_t offset_ns) {
  constexpr uint8_t kOk = 0;
  constexpr uint8_t kWarn = 1;
  const std::string word = heading_status_word(estimate.heading_status());
  ros_diag::DiagnosticStatus_ status;
  status.level(estimate.heading_status() == msg::HEADING_VERIFIED ? kOk : kWarn);
  status.name("poise/" + filter + "/heading");
  status.message(word);
  status.hardware_id(estimate.sensor_id().to_string());
  const double var = estimate.attitude_covariance()[8];
  std::ostringstream sigma;
  sigma << (var >= 0.0 ? std::sqrt(var) * (180.0 / 3.14159265358979323846) : -1.0);
  ros_diag::KeyValue_ kv_status;
  kv_status.key("heading_status");
  kv_status.value(word);
  ros_diag::KeyValue_ kv_sigma;
  kv_sigma.key("yaw_sigma_deg");
  kv_sigma.value(sigma.str());
  status.values({kv_status, kv_sigma});
  ros_diag::DiagnosticArray_ out;
  out.header(header(estimate.header().stamp_ns(), frames.world, offset_ns));
  out.status({status});
  return out;
}

ros_sensor::Imu_ sample_to_imu(const msg::ImuSample& sample, const Frames& frames, int64_t offset_ns) {
  ros_sensor::Imu_ out;
  out.header(header(sample.header().stamp_ns(), frames.body, offset_ns));
  ros_geo::Quaternion_ identity;
  identity.w(1.0);
  out.orientation(identity);
  out.orientation_covariance(presence<9>(false));
  const bool gyro = sample.valid().gyro();
  const bool accel = sample.valid().accel();
  out.angular_velocity(gyro ? vec(sample.gyro_rps()) : vec(0, 0, 0));
  out.angular_velocity_covariance(presence<9>(gyro));
  out.linear_acceleration(accel ? vec(sample.accel_mps2()) : vec(0, 0, 0));
  out.linear_acceleration_covariance(presence<9>(accel));
  return out;
}

std::optional<ros_sensor::MagneticField_> sample_to_mag(const msg::ImuSample& sample, const Frames& frames,
                                                        int64_t offset_ns) {
  if (!sample.valid().mag()) {
    return std::nullopt;
  }
  constexpr double kTeslaPerMicrotesla = 1e-6;
  ros_sensor::MagneticField_ out;
  out.header(header(sample.header().stamp_ns(), frames.body, offset_ns));
  out.magnetic_field(vec(sample.mag_ut().x() * kTeslaPerMicrotesla, sample.mag_ut().y() * kTeslaPerMicrotesla,
                         sample.mag_ut().z() * kTeslaPerMicrotesla));
  out.magnetic_field_covariance(presence<9>(true));
  return out;
}

std::optional<ros_sensor::FluidPressure_> sample_to_pressure(const msg::ImuSample& sample,
                                                             const Frames& frames, int64_t offset_ns) {
  if (!sample.valid().pressure()) {
    return std::nullopt;
  }
  ros_sensor::FluidPressure_ out;
  out.header(header(sample.header().stamp_ns(), frames.body, offset_ns));
  out.fluid_pressure(sample.pressure_pa());
  out.variance(0.0);  // unknown
  return out;
}

std::array<double, 36> pose_covariance(const msg::PoseEstimate& estimate) {
  // poise 9x9 order [p(0..2) v(3..5) theta(6..8)] -> ROS 6x6 [p(0..2) rot(3..5)].
  const auto source = [](std::size_t i) { return i < 3 ? i : i + 3; };
  std::array<double, 36> out{};
  for (std::size_t r = 0; r < 6; ++r) {
    for (std::size_t c = 0; c < 6; ++c) {
      out[r * 6 + c] = estimate.covariance()[source(r) * 9 + source(c)];
    }
  }
  return out;
}

ros_geo::PoseWithCovarianceStamped_ pose_to_ros(const msg::PoseEstimate& estimate, const Frames& frames,
                                                int64_t offset_ns) {
  ros_geo::PoseWithCovarianceStamped_ out;
  out.header(header(estimate.header().stamp_ns(), frames.world, offset_ns));
  ros_geo::Point_ p;
  p.x(estimate.position_m().x());
  p.y(estimate.position_m().y());
  p.z(estimate.position_m().z());
  out.pose().pose().position(p);
  out.pose().pose().orientation(quat(estimate.q_world_body()));
  out.pose().covariance(pose_covariance(estimate));
  return out;
}

ros_nav::Odometry_ pose_to_odometry(const msg::PoseEstimate& estimate, const msg::ImuSample* sample,
                                    const Frames& frames, int64_t offset_ns) {
  const ros_geo::PoseWithCovarianceStamped_ pose = pose_to_ros(estimate, frames, offset_ns);
  ros_nav::Odometry_ out;
  out.header(pose.header());
  out.child_frame_id(frames.body);
  out.pose(pose.pose());
  // Velocity into the body frame (ROS: twist in child_frame_id), its covariance with it.
  const Eigen::Matrix3d r = eigen(estimate.q_world_body()).normalized().toRotationMatrix();
  const Eigen::Vector3d v_world(estimate.velocity_mps().x(), estimate.velocity_mps().y(),
                                estimate.velocity_mps().z());
  Eigen::Matrix3d c_world;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      c_world(i, j) = estimate.covariance()[static_cast<std::size_t>((3 + i) * 9 + 3 + j)];
    }
  }
  const Eigen::Vector3d v_body = r.transpose() * v_world;
  const Eigen::Matrix3d c_body = r.transpose() * c_world * r;
  const bool gyro = sample != nullptr && sample->valid().gyro();
  out.twist().twist().linear(vec(v_body.x(), v_body.y(), v_body.z()));
  out.twist().twist().angular(gyro ? vec(sample->gyro_rps()) : vec(0, 0, 0));
  std::array<double, 36> cov{};
  for (std::size_t i = 0; i < 3; ++i) {
    for (std::size_t j = 0; j < 3; ++j) {
      cov[i * 6 + j] = c_body(static_cast<int>(i), static_cast<int>(j));
    }
    cov[(3 + i) * 6 + 3 + i] = gyro ? 0.0 : -1.0;
  }
  out.twist().covariance(cov);
  return out;
}

ros_nav::Odometry_ altitude_to_odometry(const msg::AltitudeEstimate& estimate, const Frames& frames,
                                        int64_t offset_ns) {
  ros_nav::Odometry_ out;
  out.header(header(estimate.header().stamp_ns(), frames.world, offset_ns));
  out.child_frame_id(frames.world);
  ros_geo::Point_ p;
  p.z(estimate.height_m());
  out.pose().pose().position(p);
  ros_geo::Quaternion_ identity;
  identity.w(1.0);
  out.pose().pose().orientation(identity);
  std::array<double, 36> pose_cov{};
  std::array<double, 36> twist_cov{};
  for (std::size_t i = 0; i < 6; ++i) {
    pose_cov[i * 6 + i] = i == 2 ? 0.0 : -1.0;   // z present (variance unknown), the rest absent
    twist_cov[i * 6 + i] = i == 2 ? 0.0 : -1.0;  // vz present, the rest absent
  }
  out.pose().covariance(pose_cov);
  out.twist().twist().linear(vec(0.0, 0.0, estimate.vertical_velocity_mps()));
  out.twist().covariance(twist_cov);
  return out;
}

ros_tf::TFMessage_ to_tf(int64_t stamp_ns, const msg::Quaternion& q_world_body,
                         const msg::Vector3& position_m, const Frames& frames, int64_t offset_ns) {
  ros_geo::TransformStamped_ t;
  t.header(header(stamp_ns, frames.world, offset_ns));
  t.child_frame_id(frames.body);
  t.transform().translation(vec(position_m));
  t.transform().rotation(quat(q_world_body));
  ros_tf::TFMessage_ out;
  out.transforms().push_back(t);
  return out;
}

bool all_finite(const ros_sensor::Imu_& m) {
  return finite(m.orientation()) && finite(m.orientation_covariance()) && finite(m.angular_velocity()) &&
         finite(m.angular_velocity_covariance()) && finite(m.linear_acceleration()) &&
         finite(m.linear_acceleration_covariance());
}
bool all_finite(const ros_sensor::MagneticField_& m) {
  return finite(m.magnetic_field()) && finite(m.magnetic_field_covariance());
}
bool all_finite(const ros_sensor::FluidPressure_& m) {
  return std::isfinite(m.fluid_pressure()) && std::isfinite(m.variance());
}
bool all_finite(const ros_geo::PoseWithCovarianceStamped_& m) { return finite(m.pose()); }
bool all_finite(const ros_nav::Odometry_& m) {
  return finite(m.pose()) && finite(m.twist().twist().linear()) && finite(m.twist().twist().angular()) &&
         finite(m.twist().covariance());
}
bool all_finite(const ros_tf::TFMessage_& m) {
  for (const auto& t : m.transforms()) {
    if (!finite(t.transform().translation()) || !finite(t.transform().rotation())) {
      return false;
    }
  }
  return true;
}

bool all_finite(const ros_diag::DiagnosticArray_& /*m*/) { return true; }  // text only

std::string dds_topic(const std::string& ros_name) {
  const auto bad = [&ros_name](const std::string& why) {
    return std::invalid_argument("'" + ros_name + "' is not a ROS 2 topic name: " + why);
  };
  if (ros_name.empty() || ros_name == "/") {
    throw bad("empty");
  }
  const std::string name = ros_name.front() == '/' ? ros_name.substr(1) : ros_name;
  if (name.back() == '/') {
    throw bad("it ends with '/'");
  }
  bool token_start = true;
  for (char c : name) {
    if (c == '/') {
      if (token_start) {
        throw bad("empty token ('//')");
      }
      token_start = true;
      continue;
    }
    if (!(std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_')) {
      throw bad(std::string("character '") + c + "' (use [A-Za-z0-9_/])");
    }
    if (token_start && std::isdigit(static_cast<unsigned char>(c)) != 0) {
      throw bad("a token starts with a digit");
    }
    token_start = false;
  }
  return "rt/" + name;
}

}  // namespace poise::ros2
