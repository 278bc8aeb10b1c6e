// Every topic type survives a publisher -> subscriber round trip with all fields equal, within one
// process and across two processes.
#include "type_cases.h"

#include "poise/dds/participant.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <chrono>
#include <mutex>
#include <optional>

namespace poise::testing {
namespace {

using namespace std::chrono_literals;
constexpr auto kDeliveryTimeout = 15s;  // discovery + delivery on loopback; generous for CI load

template <typename Case>
class RoundTrip : public ::testing::Test {};

using AllCases = ::testing::Types<ImuCase, VehicleInputCase, TagDetectionsCase, VisionPoseCase,
                                  AttitudeCase, PoseEstimateCase, AltitudeCase, DiagnosticsCase>;

class CaseNames {
 public:
  template <typename T>
  static std::string GetName(int /*index*/) {
    return T::kName;
  }
};
TYPED_TEST_SUITE(RoundTrip, AllCases, CaseNames);

/// Collects the first sample a reader receives.
template <typename Case>
class FirstSample {
 public:
  void set(const typename Case::Message& m) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!message_) {
      message_ = m;
    }
  }
  std::optional<typename Case::Message> get() {
    std::lock_guard<std::mutex> lock(mutex_);
    return message_;
  }

 private:
  std::mutex mutex_;
  std::optional<typename Case::Message> message_;
};

TYPED_TEST(RoundTrip, InOneProcessAllFieldsEqual) {
  using Case = TypeParam;
  DomainLease domain;
  dds::Participant pub_participant({domain.id(), "", "", "test_pub"});
  dds::Participant sub_participant({domain.id(), "", "", "test_sub"});
  FirstSample<Case> first;
  dds::Reader<typename Case::PubSubType> reader(
      sub_participant, Case::kTopic,
      [&first](const typename Case::Message& m, const auto& /*info*/) { first.set(m); });
  dds::Writer<typename Case::PubSubType> writer(pub_participant, Case::kTopic);
  const auto sent = Case::make(3);
  const bool received = wait_until(
      [&] {
        writer.write(sent);
        sleep_ms(10);
        return first.get().has_value();
      },
      kDeliveryTimeout);
  ASSERT_TRUE(received) << "no sample within the timeout on domain " << domain.id();
  EXPECT_TRUE(*first.get() == sent) << "a field changed in transit";
  EXPECT_FALSE(*first.get() == Case::make(4)) << "the equality oracle cannot tell samples apart";
}

TYPED_TEST(RoundTrip, AcrossTwoProcessesAllFieldsEqual) {
  using Case = TypeParam;
  DomainLease domain;
  dds::Participant participant({domain.id(), "", "", "test_sub"});
  FirstSample<Case> first;
  dds::Reader<typename Case::PubSubType> reader(
      participant, Case::kTopic,
      [&first](const typename Case::Message& m, const auto& /*info*/) { first.set(m); });
  constexpr int kSalt = 11;
  Child peer({bin("poise_dds_peer"), Case::kName, std::to_string(domain.id()),
              std::to_string(kSalt), "15000"});
  const bool received = wait_until([&] { return first.get().has_value(); }, kDeliveryTimeout);
  ASSERT_TRUE(received) << "no sample from the peer process; its output:\n" << peer.output();
  EXPECT_TRUE(*first.get() == Case::make(kSalt)) << "a field changed in transit";
}

}  // namespace
}  // namespace poise::testing
