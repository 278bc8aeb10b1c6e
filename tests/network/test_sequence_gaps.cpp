// poise::dds::SequenceGaps: lost-sample accounting from header.seq, with explicit oracles.
#include "poise/dds/sequence_gaps.h"

#include <gtest/gtest.h>

namespace poise::dds {
namespace {

TEST(SequenceGaps, ConsecutiveSamplesLoseNothing) {
  SequenceGaps g;
  EXPECT_TRUE(g.on_sample("imu0", 5, "w1").first);
  for (uint32_t s = 6; s < 20; ++s) {
    const auto e = g.on_sample("imu0", s, "w1");
    EXPECT_EQ(e.lost, 0U);
    EXPECT_FALSE(e.first || e.restart || e.duplicate);
  }
  const auto t = g.totals("imu0");
  EXPECT_EQ(t.received, 15U);
  EXPECT_EQ(t.lost, 0U);
  EXPECT_EQ(t.gaps, 0U);
}

TEST(SequenceGaps, JumpCountsTheMissingSamples) {
  SequenceGaps g;
  g.on_sample("imu0", 10, "w1");
  EXPECT_EQ(g.on_sample("imu0", 14, "w1").lost, 3U);  // 11, 12, 13 missing
  EXPECT_EQ(g.on_sample("imu0", 15, "w1").lost, 0U);
  EXPECT_EQ(g.on_sample("imu0", 1015, "w1").lost, 999U);
  const auto t = g.totals("imu0");
  EXPECT_EQ(t.lost, 1002U);
  EXPECT_EQ(t.gaps, 2U);
  EXPECT_EQ(t.received, 4U);
}

TEST(SequenceGaps, WrapAroundIsOneStep) {
  SequenceGaps g;
  g.on_sample("imu0", 0xFFFFFFFEU, "w1");
  EXPECT_EQ(g.on_sample("imu0", 0xFFFFFFFFU, "w1").lost, 0U);
  EXPECT_EQ(g.on_sample("imu0", 0U, "w1").lost, 0U);
  EXPECT_EQ(g.on_sample("imu0", 2U, "w1").lost, 1U);
  EXPECT_EQ(g.totals("imu0").restarts, 0U);
}

TEST(SequenceGaps, NewWriterIsARestartNotALoss) {
  SequenceGaps g;
  g.on_sample("imu0", 500, "w1");
  const auto e = g.on_sample("imu0", 0, "w2");  // restarted publisher starts over
  EXPECT_TRUE(e.restart);
  EXPECT_EQ(e.lost, 0U);
  const auto later = g.on_sample("imu0", 900, "w3");  // restarted, first samples unmatched
  EXPECT_TRUE(later.restart);
  EXPECT_EQ(later.lost, 0U);
  EXPECT_EQ(g.totals("imu0").restarts, 2U);
  EXPECT_EQ(g.totals("imu0").lost, 0U);
}

TEST(SequenceGaps, BackwardsAndDuplicatesFromOneWriter) {
  SequenceGaps g;
  g.on_sample("imu0", 100, "w1");
  EXPECT_TRUE(g.on_sample("imu0", 100, "w1").duplicate);
  const auto back = g.on_sample("imu0", 40, "w1");
  EXPECT_TRUE(back.restart);
  EXPECT_EQ(back.lost, 0U);
  EXPECT_EQ(g.totals("imu0").received, 2U) << "the duplicate is not counted";
}

TEST(SequenceGaps, SourcesAreIndependent) {
  SequenceGaps g;
  g.on_sample("imu0", 1, "w1");
  g.on_sample("imu1", 1, "w2");
  g.on_sample("imu0", 3, "w1");
  g.on_sample("imu1", 2, "w2");
  EXPECT_EQ(g.totals("imu0").lost, 1U);
  EXPECT_EQ(g.totals("imu1").lost, 0U);
  EXPECT_EQ(g.totals().lost, 1U);
  EXPECT_EQ(g.totals().received, 4U);
  EXPECT_EQ(g.by_source().size(), 2U);
  EXPECT_EQ(g.totals("unknown").received, 0U);
}

}  // namespace
}  // namespace poise::dds

namespace poise::dds {
namespace {

// A gap in header.seq is a lost message only where header.seq numbers the messages: not in an
// estimator's FilterDiagnostics (the seq of the step reported, published at a rate), not in types
// without a poise header.
TEST(SequenceGaps, GivenATypeThenOnlyTypesNumberingTheirMessagesCountGaps) {
  EXPECT_TRUE(header_seq_counts_messages("poise::msg::ImuSample"));
  EXPECT_TRUE(header_seq_counts_messages("poise::msg::AttitudeEstimate"));
  EXPECT_FALSE(header_seq_counts_messages("poise::msg::FilterDiagnostics"));
  EXPECT_FALSE(header_seq_counts_messages("sensor_msgs::msg::dds_::Imu_"));
  EXPECT_FALSE(header_seq_counts_messages(""));
}

}  // namespace
}  // namespace poise::dds
