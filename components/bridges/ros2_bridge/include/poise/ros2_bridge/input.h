// ROS 2 IMU input -> poise ImuSample (pure: no DDS entities, no clocks). A ROS 2 driver publishes
// sensor_msgs/Imu and, optionally, MagneticField and FluidPressure on their own topics, each at
// its own rate; the assembler pairs them by stamp into poise samples (docs/ROS2.md):
//  - each Imu waits until every configured side stream has reached its stamp, a newer Imu
//    arrives, or the side stream is stale (its newest stamp older than `stale_s`): an Imu is held
//    at most one IMU period, and not at all behind a dead stream;
//  - it then takes the side sample nearest in stamp within `pair_tolerance_s` (each side sample
//    is used once);
//  - stamps are held to the serial driver's plausibility rule (issue 33): an Imu more than
//    `max_jump_s` from the last accepted one (a day ahead, INT32_MAX s, an hour back) is held, not
//    adopted; the time base moves only when `reanchor_samples` consecutive such Imu agree with
//    each other (each 0 < dt <= max_jump_s after the one before), and they are then emitted. A
//    sample that agrees with the old time base ends the run: the held ones are rejected and
//    counted (imu_stamp_jump). A side sample more than max_jump_s from the IMU time base is
//    rejected and counted (mag_stamp_jump, pressure_stamp_jump): it must not stop the pairing.
// Every input is hostile: a message that cannot become a valid sample is rejected and counted by
// reason (the shared sample check's reasons, poise/core/sample_check.h, plus bad_stamp), never
// repaired; a bad magnetometer or pressure drops that channel of the sample, counted.
#pragma once

#include "poise/core/sample_check.h"
#include "poise/core/types.h"
#include "poise/ros2_bridge/convert.h"

#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <vector>

namespace poise::ros2 {

struct InputConfig {
  bool mag = false;                  ///< a MagneticField topic is configured
  bool pressure = false;             ///< a FluidPressure topic is configured
  double pair_tolerance_s = 0.0025;  ///< largest |stamp difference| of a pair, s
  double stale_s = 0.5;              ///< a side stream this far behind is not waited for, s
  int64_t offset_ns = 0;             ///< header.stamp - stamp_ns (see convert.h)
  SampleLimits limits;               ///< physical ranges (the cores' defaults)
  double min_pressure_pa = 1.0e3;    ///< plausible static pressure range, Pa
  double max_pressure_pa = 2.0e5;
  double max_jump_s = 1.0;   ///< farther from the time base: a stamp jump (held, see above), s
  int reanchor_samples = 3;  ///< consecutive agreeing jumped Imu that move the time base (>= 2)
};

class ImuAssembler {
 public:
  explicit ImuAssembler(InputConfig config);

  /// Each call returns the samples completed by this message, in stamp order.
  std::vector<ImuSample> on_imu(const ros_sensor::Imu_& m);
  std::vector<ImuSample> on_mag(const ros_sensor::MagneticField_& m);
  std::vector<ImuSample> on_pressure(const ros_sensor::FluidPressure_& m);

  /// Rejections by reason: whole Imu messages ("imu_<reason>") and side messages or channels
  /// ("mag_<reason>", "pressure_<reason>"), e.g. imu_non_finite_gyro, mag_bad_stamp.
  [[nodiscard]] const std::map<std::string, uint64_t>& rejected() const { return rejected_; }
  [[nodiscard]] uint64_t rejected_total() const;
  /// Samples emitted, and how many carried a paired magnetometer / pressure.
  [[nodiscard]] uint64_t emitted() const { return emitted_; }
  [[nodiscard]] uint64_t paired_mag() const { return paired_mag_; }
  [[nodiscard]] uint64_t paired_pressure() const { return paired_pressure_; }

 private:
  struct Side {
    int64_t stamp_ns;
    Eigen::Vector3d value;  // mag (uT) or pressure in x (Pa)
  };
  struct Stream {
    bool enabled = false;
    int64_t newest_ns = -1;  // newest stamp received (-1: none yet)
    std::deque<Side> buffer;
  };
  void reject(const std::string& reason) { ++rejected_[reason]; }
  void add_side(Stream& stream, Side side);
  /// Emits the pending samples that may go (see the file comment).
  std::vector<ImuSample> drain();
  bool waits_for(const Stream& stream, int64_t stamp_ns) const;
  /// Removes and returns the side sample nearest `stamp_ns` within the tolerance.
  bool take_nearest(Stream& stream, int64_t stamp_ns, Side& out) const;
  /// True when `stamp_ns` is more than max_jump_s from `base_ns` (either way).
  [[nodiscard]] bool far(int64_t stamp_ns, int64_t base_ns) const;
  /// Holds a jumped Imu (see the file comment); returns what it releases.
  std::vector<ImuSample> on_jump(const ImuSample& s);
  /// The time base moved to `base_ns`: side samples far from it are dropped (counted).
  void rebase_sides(int64_t base_ns);
  void rebase_side(Stream& stream, int64_t base_ns, const char* reason);

  InputConfig config_;
  int64_t tolerance_ns_;
  int64_t stale_ns_;
  int64_t last_stamp_ns_ = -1;  // last Imu accepted (stamps must increase)
  int64_t jump_ns_;
  std::vector<ImuSample> jumped_;  // consecutive jumped Imu that agree, held
  uint32_t seq_ = 0;
  std::deque<ImuSample> pending_;
  Stream mag_;
  Stream pressure_;
  std::map<std::string, uint64_t> rejected_;
  uint64_t emitted_ = 0;
  uint64_t paired_mag_ = 0;
  uint64_t paired_pressure_ = 0;
};

}  // namespace poise::ros2
