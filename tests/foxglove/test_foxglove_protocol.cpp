// The Foxglove protocol layer without sockets: server messages, the Message Data frame byte by
// byte, every kind of malformed client request, subscriptions, the bounded queue, and the panel
// messages against hand-computed values.
#include "poise/foxglove/panels.h"
#include "poise/foxglove/protocol.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <set>

namespace poise::foxglove {
namespace {

using nlohmann::json;

constexpr double kExact = 1e-15;  // values copied or normalised from exact inputs, dimensionless

TEST(FoxgloveProtocol, GivenAPayloadThenTheMessageDataFrameIsOpcodeSubscriptionTimeAndPayloadLittleEndian) {
  const std::uint8_t payload[] = {0x00, 0x01, 0x00, 0x00, 0xAB};
  const std::string f = message_data_frame(0x01020304u, 0x1122334455667788ull, payload, sizeof payload);
  const std::string expected("\x01\x04\x03\x02\x01\x88\x77\x66\x55\x44\x33\x22\x11\x00\x01\x00\x00\xAB", 18);
  EXPECT_EQ(f, expected);
  EXPECT_EQ(kMessageDataHeaderBytes, 13u);
}

TEST(FoxgloveProtocol, GivenChannelsThenAdvertiseServerInfoAndStatusFollowTheSpec) {
  const json a = json::parse(advertise_json({{3, "imu", "cdr", "poise::msg::ImuSample", "module poise {};", "omgidl"}}));
  EXPECT_EQ(a["op"], "advertise");
  ASSERT_EQ(a["channels"].size(), 1u);
  EXPECT_EQ(a["channels"][0]["id"], 3);
  EXPECT_EQ(a["channels"][0]["topic"], "imu");
  EXPECT_EQ(a["channels"][0]["encoding"], "cdr");
  EXPECT_EQ(a["channels"][0]["schemaName"], "poise::msg::ImuSample");
  EXPECT_EQ(a["channels"][0]["schemaEncoding"], "omgidl");
  const json u = json::parse(unadvertise_json({3, 4}));
  EXPECT_EQ(u["op"], "unadvertise");
  EXPECT_EQ(u["channelIds"], json::array({3, 4}));
  const json i = json::parse(server_info_json("poise", "s1"));
  EXPECT_EQ(i["op"], "serverInfo");
  EXPECT_TRUE(i["capabilities"].is_array());
  EXPECT_EQ(i["sessionId"], "s1");
  const json s = json::parse(status_json(StatusLevel::kError, std::string("bad \xff byte")));
  EXPECT_EQ(s["level"], 2);
  EXPECT_EQ(s["op"], "status");
}

TEST(FoxgloveProtocol, GivenEveryMalformedRequestThenAnErrorStatusAndNoSubscription) {
  ClientSession session;
  auto known = [](std::uint32_t id) { return id == 1 || id == 2; };
  const std::vector<std::string> bad = {
      "", "{", "\xff\xfe", "[1,2]", "42", "{\"subscriptions\":[]}", "{\"op\":7}", "{\"op\":\"launch\"}",
      "{\"op\":\"getParameters\"}", "{\"op\":\"advertise\",\"channels\":[]}", "{\"op\":\"subscribe\"}",
      "{\"op\":\"subscribe\",\"subscriptions\":{}}", "{\"op\":\"subscribe\",\"subscriptions\":[5]}",
      "{\"op\":\"subscribe\",\"subscriptions\":[{\"id\":1}]}",
      "{\"op\":\"subscribe\",\"subscriptions\":[{\"id\":-1,\"channelId\":1}]}",
      "{\"op\":\"subscribe\",\"subscriptions\":[{\"id\":1.5,\"channelId\":1}]}",
      "{\"op\":\"subscribe\",\"subscriptions\":[{\"id\":4294967296,\"channelId\":1}]}",
      "{\"op\":\"subscribe\",\"subscriptions\":[{\"id\":1,\"channelId\":3}]}",
      "{\"op\":\"unsubscribe\"}", "{\"op\":\"unsubscribe\",\"subscriptionIds\":[\"a\"]}",
      std::string(100000, '[') + std::string(100000, ']')};
  for (const auto& text : bad) {
    const auto r = session.handle_text(text, known);
    ASSERT_EQ(r.replies.size(), 1u) << text.substr(0, 80);
    EXPECT_EQ(r.replies[0].level, StatusLevel::kError) << text.substr(0, 80) << ": " << r.replies[0].message;
    EXPECT_FALSE(r.subscriptions_changed);
  }
  EXPECT_TRUE(session.subscriptions().empty());
}

TEST(FoxgloveProtocol, GivenSubscriptionsThenOnePerChannelAndIdsNotReusedWhileActive) {
  ClientSession session;
  auto known = [](std::uint32_t id) { return id == 1 || id == 2; };
  auto r = session.handle_text(R"({"op":"subscribe","subscriptions":[{"id":10,"channelId":1},{"id":11,"channelId":2}]})", known);
  EXPECT_TRUE(r.replies.empty());
  EXPECT_TRUE(r.subscriptions_changed);
  EXPECT_EQ(session.subscription_for(1), 10u);
  EXPECT_EQ(session.subscription_for(2), 11u);
  r = session.handle_text(R"({"op":"subscribe","subscriptions":[{"id":10,"channelId":2},{"id":12,"channelId":1}]})", known);
  ASSERT_EQ(r.replies.size(), 1u);  // id in use; channel already subscribed: one status per request
  EXPECT_EQ(r.replies[0].message, "subscribe: 2 of 2 refused: subscription id 10 is already in use (and 1 more)");
  r = session.handle_text(R"({"op":"unsubscribe","subscriptionIds":[10, 99]})", known);
  ASSERT_EQ(r.replies.size(), 1u);
  EXPECT_EQ(r.replies[0].level, StatusLevel::kWarning);
  EXPECT_FALSE(session.subscription_for(1).has_value());
  r = session.handle_text(R"({"op":"subscribe","subscriptions":[{"id":10,"channelId":1}]})", known);
  EXPECT_TRUE(r.replies.empty());  // the id is free again
  EXPECT_TRUE(session.channel_removed(2));
  EXPECT_FALSE(session.subscription_for(2).has_value());
  EXPECT_EQ(ClientSession::binary_refused(6).level, StatusLevel::kError);
}

// Issue 33: 100 requests of 32000 invalid ids each were answered id by id (3.2 million statuses,
// 6.7 s of the bridge's CPU). A request is answered with one status however many entries it
// refuses, and a list longer than kMaxEntriesPerRequest is refused whole, unread.
TEST(FoxgloveProtocol, GivenARequestFloodingInvalidIdsThenOneStatusPerRequestAndLongListsRefusedUnread) {
  ClientSession session;
  auto known = [](std::uint32_t id) { return id == 1; };
  std::string ids;
  for (int i = 0; i < 32000; ++i) {
    ids += (i ? "," : "") + std::to_string(i % 10);
  }
  auto r = session.handle_text(R"({"op":"unsubscribe","subscriptionIds":[)" + ids + "]}", known);
  ASSERT_EQ(r.replies.size(), 1u);
  EXPECT_EQ(r.replies[0].level, StatusLevel::kError);
  EXPECT_EQ(r.replies[0].message, "unsubscribe: 32000 entries in one request, more than the 256 accepted: refused");
  std::string subs;
  for (std::size_t i = 0; i < ClientSession::kMaxEntriesPerRequest; ++i) {
    subs += (i ? "," : "") + std::string(R"({"id":)") + std::to_string(i) + R"(,"channelId":)" + std::to_string(100 + i) + "}";
  }
  r = session.handle_text(R"({"op":"subscribe","subscriptions":[)" + subs + "]}", known);
  ASSERT_EQ(r.replies.size(), 1u);
  EXPECT_EQ(r.replies[0].message, "subscribe: 256 of 256 refused: unknown channel 100 (and 255 more)");
  EXPECT_TRUE(session.subscriptions().empty());
}

TEST(FoxgloveProtocol, GivenAFullQueueThenTheOldestFramesAreDroppedAndCounted) {
  FrameQueue q(3, 1000);
  for (int i = 0; i < 5; ++i) {
    q.push(std::string(10, static_cast<char>('a' + i)));
  }
  EXPECT_EQ(q.size(), 3u);
  EXPECT_EQ(q.dropped(), 2u);
  EXPECT_EQ(q.bytes(), 30u);
  std::string f;
  ASSERT_TRUE(q.pop(f));
  EXPECT_EQ(f[0], 'c');
  FrameQueue bytes(100, 25);  // the byte bound
  for (int i = 0; i < 4; ++i) {
    bytes.push(std::string(10, 'x'));
  }
  EXPECT_EQ(bytes.size(), 2u);
  EXPECT_EQ(bytes.dropped(), 2u);
  bytes.push(std::string(100, 'y'));  // larger than the bound alone: kept, the rest dropped
  EXPECT_EQ(bytes.size(), 1u);
  EXPECT_EQ(bytes.dropped(), 4u);
}

schema::Value leaf(double d) {
  schema::Value v;
  v.kind = schema::Value::Kind::kFloat;
  v.d = d;
  return v;
}

schema::Value node(std::vector<std::pair<std::string, schema::Value>> fields) {
  schema::Value v;
  v.kind = schema::Value::Kind::kStruct;
  v.fields = std::move(fields);
  return v;
}

schema::Value attitude(std::int64_t stamp, double w, double x, double y, double z) {
  schema::Value s;
  s.kind = schema::Value::Kind::kInt;
  s.i = stamp;
  schema::Value trusted;
  trusted.kind = schema::Value::Kind::kBool;
  trusted.b = true;
  schema::Value filter;
  filter.kind = schema::Value::Kind::kString;
  filter.s = "parallel_kf";
  return node({{"header", node({{"stamp_ns", s}})},
               {"filter_id", filter},
               {"q_world_body", node({{"w", leaf(w)}, {"x", leaf(x)}, {"y", leaf(y)}, {"z", leaf(z)}})},
               {"roll_rad", leaf(M_PI / 2)},
               {"pitch_rad", leaf(0.0)},
               {"yaw_rad", leaf(std::nan(""))},
               {"mag_disturbance_world_ut", node({{"x", leaf(1.0)}, {"y", leaf(-2.0)}, {"z", leaf(3.0)}})},
               {"mag_disturbance_norm_ut", leaf(std::sqrt(14.0))},
               {"mag_disturbance_angle_rad", leaf(M_PI / 180.0)},
               {"mag_trusted", trusted}});
}

TEST(FoxglovePanels, GivenAnAttitudeThenTheFrameTransformIsTheNormalisedQuaternionAtTheDisplayOffset) {
  // q = 2 * (cos 45, sin 45, 0, 0): normalised to (0.7071..., 0.7071..., 0, 0).
  const auto text = frame_transform_json("poise::msg::AttitudeEstimate",
                                         attitude(3'000'000'123, 2 * M_SQRT1_2, 2 * M_SQRT1_2, 0, 0),
                                         "world", "parallel_kf", 0.6, 1'000'000'000);
  ASSERT_TRUE(text);
  const json j = json::parse(*text);
  EXPECT_EQ(j["timestamp"]["sec"], 4);
  EXPECT_EQ(j["timestamp"]["nsec"], 123);
  EXPECT_EQ(j["parent_frame_id"], "world");
  EXPECT_EQ(j["child_frame_id"], "parallel_kf");
  EXPECT_NEAR(j["rotation"]["w"].get<double>(), M_SQRT1_2, kExact);
  EXPECT_NEAR(j["rotation"]["x"].get<double>(), M_SQRT1_2, kExact);
  EXPECT_EQ(j["rotation"]["y"].get<double>(), 0.0);
  EXPECT_EQ(j["translation"]["x"].get<double>(), 0.6);
  EXPECT_EQ(j["translation"]["y"].get<double>(), 0.0);
  // Never a NaN or a zero quaternion on the wire.
  EXPECT_FALSE(frame_transform_json("poise::msg::AttitudeEstimate", attitude(1, std::nan(""), 0, 0, 0), "world", "a", 0, 0));
  EXPECT_FALSE(frame_transform_json("poise::msg::AttitudeEstimate", attitude(1, 0, 0, 0, 0), "world", "a", 0, 0));
  EXPECT_FALSE(frame_transform_json("poise::msg::ImuSample", attitude(1, 1, 0, 0, 0), "world", "a", 0, 0));
  EXPECT_FALSE(frame_transform_json("poise::msg::AttitudeEstimate", attitude(-5, 1, 0, 0, 0), "world", "a", 0, 0));
}

TEST(FoxglovePanels, GivenAnAttitudeThenThePlotHasDegreesTheDisturbanceAndTrustWithNullForNaN) {
  const auto text = attitude_plot_json(attitude(2'500'000'000, 1, 0, 0, 0), 0);
  ASSERT_TRUE(text);
  const json j = json::parse(*text);
  EXPECT_EQ(j["timestamp"]["sec"], 2);
  EXPECT_EQ(j["timestamp"]["nsec"], 500'000'000);
  EXPECT_EQ(j["filter"], "parallel_kf");
  EXPECT_NEAR(j["rpy_deg"]["x"].get<double>(), 90.0, 1e-12);
  EXPECT_TRUE(j["rpy_deg"]["z"].is_null());
  EXPECT_EQ(j["mag_disturbance_world_ut"]["y"].get<double>(), -2.0);
  EXPECT_NEAR(j["mag_disturbance_norm_ut"].get<double>(), std::sqrt(14.0), kExact);
  EXPECT_NEAR(j["mag_disturbance_angle_deg"].get<double>(), 1.0, 1e-12);
  EXPECT_EQ(j["mag_trusted"], 1);
  EXPECT_EQ(json::parse(frame_transform_schema())["title"], "foxglove.FrameTransform");
  EXPECT_EQ(json::parse(attitude_plot_schema())["title"], "poise.AttitudePlot");
}

TEST(FoxglovePanels, GivenAnUnverifiedHeadingThenThePlotSaysSoWithTheYawSigmaFromTheCovariance) {
  schema::Value a = attitude(2'500'000'000, 1, 0, 0, 0);
  schema::Value status;
  status.kind = schema::Value::Kind::kEnum;
  status.u = 2;
  status.s = "HEADING_UNVERIFIED";  // as the CDR decoder names the IDL enumerator
  schema::Value cov;
  cov.kind = schema::Value::Kind::kList;
  for (int k = 0; k < 9; ++k) {
    cov.items.push_back(leaf(k == 8 ? std::pow(20.0 * M_PI / 180.0, 2) : 0.0));  // yaw sigma 20 deg
  }
  a.fields.emplace_back("attitude_covariance", cov);
  a.fields.emplace_back("heading_status", status);
  const json j = json::parse(*attitude_plot_json(a, 0));
  EXPECT_EQ(j["heading_status"], "unverified");
  EXPECT_EQ(j["heading_verified"], 0);
  constexpr double kSqrtTolDeg = 1e-12;
  EXPECT_NEAR(j["yaw_sigma_deg"].get<double>(), 20.0, kSqrtTolDeg);
  a.fields.back().second.s = "HEADING_VERIFIED";
  EXPECT_EQ(json::parse(*attitude_plot_json(a, 0))["heading_verified"], 1);
  const json schema = json::parse(attitude_plot_schema());
  EXPECT_TRUE(schema["properties"].contains("heading_status"));
  EXPECT_TRUE(schema["properties"].contains("yaw_sigma_deg"));
}

TEST(FoxglovePanels, GivenTopicsThenChildFramesAndSlotsAreFixedForPoiseFilters) {
  EXPECT_EQ(child_frame("attitude/parallel_kf"), "parallel_kf");
  EXPECT_EQ(child_frame("truth/attitude"), "truth");
  EXPECT_EQ(child_frame("pose/selective_ekf"), "selective_ekf_pose");
  EXPECT_EQ(child_frame("truth/pose"), "truth_pose");
  EXPECT_EQ(child_frame("vision_pose"), "camera");
  EXPECT_EQ(child_frame("a/b"), "a_b");
  FrameLayout layout(0.5);
  EXPECT_EQ(layout.offset_m("mine"), 2.5);  // first name beyond the 5 fixed slots
  EXPECT_EQ(layout.offset_m("truth"), 0.0);
  EXPECT_EQ(layout.offset_m("gauss_newton"), 1.5);
  EXPECT_EQ(layout.offset_m("other"), 3.0);
  EXPECT_EQ(layout.offset_m("mine"), 2.5);
}

}  // namespace
}  // namespace poise::foxglove
