// Serial IMU line protocol: parsing, validation and formatting (pure, no I/O, no clocks).
//
// One ASCII line per sample (full description: docs/SERIAL_PROTOCOL.md):
//   $IMU,<seq>,<t_us>,<ax>,<ay>,<az>,<gx>,<gy>,<gz>,<mx>,<my>,<mz>,<p_pa>,<temp_c>*<CS>\r\n
//     SI values as decimal floats (m/s^2, rad/s, uT, Pa, C); p_pa and temp_c may be empty; the
//     three mag fields may be empty together (no magnetometer, or it saturated).
//   $RAW,<seq>,<t_us>,<ax>,<ay>,<az>,<gx>,<gy>,<gz>,<mx>,<my>,<mz>,<p_pa>,<temp>*<CS>\r\n
//     register counts as signed decimal integers (MPU6050 accel/gyro, HMC5883L mag in X,Y,Z order,
//     MPU6050 TEMP_OUT), pressure in integer Pa (BMP180 compensated on the board); converted to SI
//     with RawScale. p_pa and temp may be empty; mag may be empty (all three) and an HMC5883L
//     overflow count (-4096) on any axis also marks the magnetometer invalid for that sample.
//   CS: two hex digits, XOR of every byte strictly between '$' and '*'.
//   $INF,<version>,<chip>,<setting>,<accel_delay_us>,<gyro_delay_us>*CS\r\n
//     what the sensor says about itself (version 1): the chip, its low-pass setting (MPU6050
//     DLPF_CFG) and, optionally, its group delays; resolved by resolve_sensor_info (sensor_info.h).
//   Lines starting with '#' are informational messages from the firmware (not samples).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include <Eigen/Core>

namespace poise::imu {

/// Longest accepted line, bytes, excluding the line terminator.
inline constexpr std::size_t kMaxLineBytes = 255;

/// Why a line (or a run of bytes) was not turned into a sample. Every reason is counted.
enum class RejectReason : int {
  kGarbage = 0,       ///< bytes outside any "$...\n" line (noise, a line without '$')
  kOverlong,          ///< more than kMaxLineBytes before the terminator
  kTruncated,         ///< line cut short: no '*CS', or a new '$' before the terminator
  kBadChecksumField,  ///< '*' not followed by exactly two hex digits
  kChecksumMismatch,  ///< XOR checksum differs
  kUnknownSentence,   ///< talker other than IMU / RAW
  kFieldCount,        ///< wrong number of comma-separated fields
  kMissingField,      ///< a mandatory field is empty (accel, gyro, seq, t_us; or 1-2 mag axes)
  kNonNumeric,        ///< a field is not a (complete) number of the expected kind
  kNotFinite,         ///< NaN or infinity
  kOutOfRange,        ///< value outside the configured physical limits (or int16 counts)
  kDuplicateSeq,      ///< same seq as the last accepted sample
  kOutOfOrderSeq,     ///< seq older than the last accepted sample (within the reorder window)
  kTimeNotMonotonic,  ///< seq advanced but the sensor clock went backwards
  kInfoUnsupported,   ///< $INF of another version, or a chip name that is not [A-Za-z0-9_-]{1,16}
  kInfoUnknownSetting,  ///< $INF whose setting the driver's table lacks (and no delays given)
  kInfoConflict,      ///< $INF whose delays disagree with the table, or with the info in effect
  kCount
};

inline constexpr std::size_t kRejectReasonCount = static_cast<std::size_t>(RejectReason::kCount);

/// Stable snake_case name of a reason (diagnostics keys, docs).
const char* to_string(RejectReason reason);

/// Counts per reject reason.
using RejectCounts = std::array<uint64_t, kRejectReasonCount>;

/// Physical limits; a value outside them is kOutOfRange. Defaults cover a GY-87 at its widest ranges.
struct Limits {
  double accel_max_mps2 = 200.0;     ///< |component| limit, m/s^2 (MPU6050 +-16 g = 157 m/s^2)
  double gyro_max_rps = 40.0;        ///< |component| limit, rad/s (MPU6050 2000 dps = 34.9 rad/s)
  double mag_max_ut = 1000.0;        ///< |component| limit, uT (HMC5883L +-8.1 Ga = 810 uT)
  double pressure_min_pa = 20000.0;  ///< lowest plausible static pressure, Pa
  double pressure_max_pa = 120000.0; ///< highest plausible static pressure, Pa
  double temperature_min_c = -55.0;  ///< C
  double temperature_max_c = 125.0;  ///< C
};

/// Register-count scale factors for $RAW lines (MPU6050 / HMC5883L datasheets).
struct RawScale {
  double accel_lsb_per_g = 16384.0;  ///< MPU6050 AFS_SEL=0 (+-2 g); 8192, 4096, 2048 for 4/8/16 g
  double gyro_lsb_per_dps = 131.0;   ///< MPU6050 FS_SEL=0 (+-250 dps); 65.5, 32.8, 16.4
  double mag_lsb_per_gauss = 1090.0; ///< HMC5883L gain 1 (+-1.3 Ga); 1370, 820, 660, 440, ...
  double temp_lsb_per_c = 340.0;     ///< MPU6050 TEMP_OUT: T = counts / 340 + 36.53
  double temp_offset_c = 36.53;
  double g_mps2 = 9.80665;           ///< standard gravity used to convert counts/g to m/s^2
};

/// A parsed, validated, *uncalibrated* sample in the sensor's own axes.
struct RawSample {
  uint32_t seq = 0;
  uint32_t t_us = 0;  ///< sensor clock, microseconds, wraps at 2^32
  Eigen::Vector3d accel_mps2{0, 0, 0};
  Eigen::Vector3d gyro_rps{0, 0, 0};
  Eigen::Vector3d mag_ut{0, 0, 0};
  double pressure_pa = 0.0;
  double temperature_c = 0.0;
  bool has_mag = true;           ///< false: mag fields empty or saturated (mag_ut is zero)
  bool has_pressure = false;
  bool has_temperature = false;
  bool from_raw_counts = false;  ///< true for $RAW lines
};

/// The fields of a version-1 `$INF` line, checked for form only (resolve_sensor_info, in
/// sensor_info.h, gives them a meaning).
struct SensorInfoLine {
  uint32_t version = 0;
  std::string chip;           ///< e.g. "MPU6050"
  int32_t setting = -1;       ///< the chip's low-pass setting (MPU6050 DLPF_CFG); -1: field empty
  bool has_delays = false;    ///< both delay fields given (they are given together or not at all)
  uint32_t accel_delay_us = 0;
  uint32_t gyro_delay_us = 0;
};

/// Outcome of parsing one line.
struct ParseResult {
  bool ok = false;
  RejectReason reason = RejectReason::kGarbage;  ///< valid iff !ok
  bool is_info = false;                          ///< ok and a $INF line: `info`, not `sample`
  RawSample sample;                              ///< valid iff ok and !is_info
  SensorInfoLine info;                           ///< valid iff ok and is_info
};

/// Largest group delay a $INF line may give, us: the filters' imu_delay_s range [0, 0.05] s.
inline constexpr uint32_t kMaxInfoDelayUs = 50000;

/// XOR of the bytes of `payload` (the text strictly between '$' and '*').
uint8_t nmea_checksum(std::string_view payload);

/// Parses one line (without its "\r\n"; a trailing '\r' is tolerated). Stateless: sequence checks
/// are done by SequenceTracker. Never throws, never reads out of `line`.
class LineParser {
 public:
  LineParser() = default;
  LineParser(const Limits& limits, const RawScale& raw) : limits_(limits), raw_(raw) {}
  [[nodiscard]] ParseResult parse(std::string_view line) const;
  [[nodiscard]] const Limits& limits() const { return limits_; }
  [[nodiscard]] const RawScale& raw_scale() const { return raw_; }

 private:
  Limits limits_;
  RawScale raw_;
};

/// Formats an SI sample as a complete "$IMU,...*CS\r\n" line (used by the simulator and tests).
/// `decimals` digits after the point for the vectors.
std::string format_imu_line(const RawSample& s, int decimals = 5);

/// Formats register counts as a "$RAW,...*CS\r\n" line.
struct RawCounts {
  uint32_t seq = 0;
  uint32_t t_us = 0;
  std::array<int32_t, 3> accel{0, 0, 0};
  std::array<int32_t, 3> gyro{0, 0, 0};
  std::array<int32_t, 3> mag{0, 0, 0};
  bool has_mag = true;
  bool has_pressure = false;
  int32_t pressure_pa = 0;
  bool has_temperature = false;
  int32_t temperature = 0;  ///< MPU6050 TEMP_OUT counts
};
std::string format_raw_line(const RawCounts& c);

/// Formats a version-1 sensor info line "$INF,1,<chip>,<setting>,<a>,<g>*CS\r\n"; the delays are
/// left empty when !has_delays, the setting when it is negative.
std::string format_info_line(const SensorInfoLine& info);

/// Wraps a payload (text between '$' and '*') into a full line with checksum and "\r\n".
std::string wrap_payload(std::string_view payload);

}  // namespace poise::imu
