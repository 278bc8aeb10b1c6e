// The table of every poise topic type for round-trip tests: PubSubType, a default topic and a
// deterministic message factory. Shared by the in-process test and the peer process.
#pragma once

#include "sample_messages.h"

#include <string>

namespace poise::testing {

#define POISE_TYPE_CASE(Name, PubSub, Topic, Factory)   \
  struct Name {                                         \
    using PubSubType = msg::PubSub;                     \
    using Message = PubSubType::type;                   \
    static constexpr const char* kName = #Name;         \
    static constexpr const char* kTopic = Topic;        \
    static Message make(int salt) { return Factory(salt); } \
  };

POISE_TYPE_CASE(ImuCase, ImuSamplePubSubType, "imu", make_imu)
POISE_TYPE_CASE(VehicleInputCase, VehicleInputPubSubType, "vehicle_input", make_vehicle_input)
POISE_TYPE_CASE(TagDetectionsCase, TagDetectionsPubSubType, "tag_detections", make_tag_detections)
POISE_TYPE_CASE(VisionPoseCase, VisionPosePubSubType, "vision_pose", make_vision_pose)
POISE_TYPE_CASE(AttitudeCase, AttitudeEstimatePubSubType, "attitude/parallel_kf", make_attitude)
POISE_TYPE_CASE(PoseEstimateCase, PoseEstimatePubSubType, "pose/selective_ekf", make_pose_estimate)
POISE_TYPE_CASE(AltitudeCase, AltitudeEstimatePubSubType, "altitude", make_altitude)
POISE_TYPE_CASE(DiagnosticsCase, FilterDiagnosticsPubSubType, "diagnostics", make_diagnostics)

#undef POISE_TYPE_CASE

/// Calls `f.template operator()<Case>()` for the case named `name`; false if unknown.
template <typename F>
bool with_case(const std::string& name, F&& f) {
  if (name == ImuCase::kName) { f.template operator()<ImuCase>(); return true; }
  if (name == VehicleInputCase::kName) { f.template operator()<VehicleInputCase>(); return true; }
  if (name == TagDetectionsCase::kName) { f.template operator()<TagDetectionsCase>(); return true; }
  if (name == VisionPoseCase::kName) { f.template operator()<VisionPoseCase>(); return true; }
  if (name == AttitudeCase::kName) { f.template operator()<AttitudeCase>(); return true; }
  if (name == PoseEstimateCase::kName) { f.template operator()<PoseEstimateCase>(); return true; }
  if (name == AltitudeCase::kName) { f.template operator()<AltitudeCase>(); return true; }
  if (name == DiagnosticsCase::kName) { f.template operator()<DiagnosticsCase>(); return true; }
  return false;
}

}  // namespace poise::testing
