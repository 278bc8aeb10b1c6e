// Participant setup errors are clear; profiles resolve as documented.
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include "poise/dds/participant.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

namespace poise::dds {
namespace {

TEST(Participant, UnknownProfileIsAClearError) {
  testing::DomainLease domain;
  ParticipantOptions options;
  options.domain = domain.id();
  options.profile = "no_such_profile";
  try {
    Participant participant(options);
    FAIL() << "expected DdsError";
  } catch (const DdsError& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_profile"), std::string::npos) << e.what();
  }
}

TEST(Participant, UnreadableQosFileIsAClearError) {
  EXPECT_THROW(load_profiles("/nonexistent/poise_profiles.xml"), DdsError);
}

TEST(Participant, ExplicitProfileWinsOverEnvironment) {
  ParticipantOptions options;
  options.profile = "poise_udp";
  EXPECT_EQ(resolve_participant_profile(options), "poise_udp");
}

TEST(Participant, TopicNameCannotChangeType) {
  testing::DomainLease domain;
  Participant participant({domain.id(), "", "", "test"});
  Writer<msg::ImuSamplePubSubType> imu(participant, "shared_name");
  EXPECT_THROW((Writer<msg::AltitudeEstimatePubSubType>(participant, "shared_name")), DdsError);
  // Same name and type: the topic is reused.
  EXPECT_NO_THROW((Writer<msg::ImuSamplePubSubType>(participant, "shared_name")));
}

}  // namespace
}  // namespace poise::dds
