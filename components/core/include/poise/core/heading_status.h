// HeadingStatus: whether an attitude estimate's heading is backed by a field the filter trusts,
// a field of the estimate a consumer reads without parsing diagnostics (the IDL's
// AttitudeEstimate.heading_status, the ROS 2 bridge's companion topic, Foxglove's plot message).
#pragma once

#include <cstdint>

namespace poise {

/// The values and their order are the IDL's HeadingStatus (estimates.idl): 0 is the safe default
/// of a consumer that reads nothing ("no absolute heading").
enum class HeadingStatus : std::uint8_t {
  /// The filter has no absolute heading reference (6-axis, or a filter that does not estimate a
  /// heading from a field): the heading is relative to its start and drifts with the gyro.
  kNoReference = 0,
  /// Corrected by a field consistent with a verified reference (configured, seeded from the
  /// World Magnetic Model, or learnt and then consistent over the verification time).
  kVerified = 1,
  /// Not (or no longer) backed by a verified field: a cold start whose field reference is not yet
  /// verified, or a long stretch with the magnetometer gated. The heading may be far off; the
  /// heading part of the published covariance says how far.
  kUnverified = 2,
};

/// The variance of a heading uniform over +-180 deg, pi^2 / 3 rad^2 (sigma 104 deg): what a filter
/// adds to its published heading variance while nothing bounds the heading (a field reference not
/// yet verified: a start next to a magnet).
inline constexpr double kUnknownHeadingVarRad2 = 3.14159265358979323846 * 3.14159265358979323846 / 3.0;

/// "no_reference", "verified", "unverified" (the IDL's enumerators in lower case, without HEADING_).
const char* to_string(HeadingStatus status);

}  // namespace poise
