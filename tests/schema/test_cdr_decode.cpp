// CDR decoder against fastcdr: every topic type is filled with distinct values (every leaf
// different, strings at their bounds, negative and >2^53 integers), serialized by the generated
// PubSubType, decoded by the schema layer, and every leaf compared in declaration order.
#include "poise/schema/cdr.h"

#include <gtest/gtest.h>

#include <fastcdr/Cdr.h>
#include <fastcdr/FastBuffer.h>
#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace poise::schema {
namespace {

// Hands out distinct values and records, in order, the JSON each leaf must decode to.
class Leaves {
 public:
  double d() {
    ++n_;
    const double v = (static_cast<double>(n_) + 0.125) * (n_ % 2 == 0 ? -1.0 : 1.0) * 1.0e-3;
    record_float(v);
    return v;
  }
  std::int32_t i32() {
    const auto v = static_cast<std::int32_t>(-1000003 * static_cast<std::int32_t>(++n_));
    record_int(v);
    return v;
  }
  std::int64_t i64() {
    const std::int64_t v = -(std::int64_t{1} << 60) + static_cast<std::int64_t>(++n_);
    record_int(v);
    return v;
  }
  std::uint32_t u32() {
    const std::uint32_t v = 4000000000U + static_cast<std::uint32_t>(++n_);
    Value x;
    x.kind = Value::Kind::kUInt;
    x.u = v;
    expected.push_back(to_json(x));
    return v;
  }
  std::uint64_t u64() {
    const std::uint64_t v = (std::uint64_t{1} << 63) + static_cast<std::uint64_t>(++n_);
    Value x;
    x.kind = Value::Kind::kUInt;
    x.u = v;
    expected.push_back(to_json(x));
    return v;
  }
  bool b() {
    const bool v = (++n_ % 3) != 0;
    Value x;
    x.kind = Value::Kind::kBool;
    x.b = v;
    expected.push_back(to_json(x));
    return v;
  }
  std::string s(std::size_t length) {
    std::string v;
    ++n_;
    for (std::size_t k = 0; k < length; ++k) {
      v += static_cast<char>('a' + (n_ + k) % 26);
    }
    Value x;
    x.kind = Value::Kind::kString;
    x.s = v;
    expected.push_back(to_json(x));
    return v;
  }
  void header(poise::msg::Header& h) {
    h.stamp_ns(i64());
    h.seq(u32());
    h.frame_id(s(64));
  }
  void vec(poise::msg::Vector3& v) {
    v.x(d());
    v.y(d());
    v.z(d());
  }
  void quat(poise::msg::Quaternion& q) {
    q.w(d());
    q.x(d());
    q.y(d());
    q.z(d());
  }
  void pose(poise::msg::Pose& p) {
    vec(p.position_m());
    quat(p.orientation());
  }
  template <std::size_t N>
  void doubles(std::array<double, N>& a) {
    for (auto& x : a) {
      x = d();
    }
  }

  std::vector<std::string> expected;

 private:
  void record_float(double v) {
    Value x;
    x.kind = Value::Kind::kFloat;
    x.d = v;
    expected.push_back(to_json(x));
  }
  void record_int(std::int64_t v) {
    Value x;
    x.kind = Value::Kind::kInt;
    x.i = v;
    expected.push_back(to_json(x));
  }
  int n_ = 0;
};

void collect(const Value& v, std::vector<std::string>& out) {
  if (v.kind == Value::Kind::kStruct) {
    for (const auto& f : v.fields) {
      collect(f.second, out);
    }
  } else if (v.kind == Value::Kind::kList) {
    for (const auto& item : v.items) {
      collect(item, out);
    }
  } else {
    out.push_back(to_json(v));
  }
}

template <typename PubSubType, typename Msg>
std::vector<std::uint8_t> serialize(Msg& msg) {
  PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(type.m_typeSize);
  EXPECT_TRUE(type.serialize(&msg, &payload));
  return {payload.data, payload.data + payload.length};
}

// Decodes `payload` as `type` and checks every leaf against the recorded values.
Value expect_round_trip(const std::string& type, const std::vector<std::uint8_t>& payload,
                        const Leaves& leaves) {
  EXPECT_GE(payload.size(), 4U);
  EXPECT_EQ(payload[0], 0x00);
  EXPECT_EQ(payload[1], 0x01);  // CDR little endian
  const Value v = decode(TypeTable::builtin(), type, payload);
  std::vector<std::string> got;
  collect(v, got);
  EXPECT_EQ(got, leaves.expected) << type;
  EXPECT_EQ(read_header_stamp_ns(payload.data(), payload.size()),
            v.at("header.stamp_ns") != nullptr ? std::optional<std::int64_t>(v.at("header.stamp_ns")->i)
                                               : std::nullopt);
  EXPECT_TRUE(has_header_stamp(TypeTable::builtin(), type));
  return v;
}

TEST(CdrDecode, GivenAFilledImuSampleWhenSerializedByFastcdrThenEveryFieldDecodes) {
  Leaves g;
  poise::msg::ImuSample m;
  g.header(m.header());
  m.sensor_id(g.s(64));
  g.vec(m.accel_mps2());
  g.vec(m.gyro_rps());
  g.vec(m.mag_ut());
  m.pressure_pa(g.d());
  m.temperature_c(g.d());
  m.valid().accel(g.b());
  m.valid().gyro(g.b());
  m.valid().mag(g.b());
  m.valid().pressure(g.b());
  m.valid().temperature(g.b());
  const auto payload = serialize<poise::msg::ImuSamplePubSubType>(m);
  const Value v = expect_round_trip("poise::msg::ImuSample", payload, g);
  ASSERT_NE(v.at("accel_mps2.y"), nullptr);
  EXPECT_EQ(v.at("accel_mps2.y")->d, m.accel_mps2().y());
  EXPECT_EQ(v.at("sensor_id")->s, m.sensor_id().to_string());
  EXPECT_EQ(v.at("valid.mag")->b, m.valid().mag());
}

TEST(CdrDecode, GivenAFilledVehicleInputWhenSerializedByFastcdrThenEveryFieldDecodes) {
  Leaves g;
  poise::msg::VehicleInput m;
  g.header(m.header());
  m.sensor_id(g.s(0));
  m.speed_mps(g.d());
  m.speed_valid(g.b());
  expect_round_trip("poise::msg::VehicleInput", serialize<poise::msg::VehicleInputPubSubType>(m), g);
}

TEST(CdrDecode, GivenAFilledAttitudeEstimateWhenSerializedByFastcdrThenEveryFieldDecodes) {
  Leaves g;
  poise::msg::AttitudeEstimate m;
  g.header(m.header());
  m.sensor_id(g.s(5));
  m.filter_id(g.s(32));
  g.quat(m.q_world_body());
  m.roll_rad(g.d());
  m.pitch_rad(g.d());
  m.yaw_rad(g.d());
  g.doubles(m.attitude_covariance());
  g.vec(m.ext_accel_body_mps2());
  g.vec(m.ext_accel_world_mps2());
  g.vec(m.mag_disturbance_body_ut());
  g.vec(m.mag_disturbance_world_ut());
  m.mag_disturbance_norm_ut(g.d());
  m.mag_disturbance_angle_rad(g.d());
  m.mag_trusted(g.b());
  m.sources_fused(g.u32());
  g.vec(m.gyro_bias_rps());
  m.heading_status(poise::msg::HEADING_UNVERIFIED);  // an enum: decoded as its enumerator's name
  Value status;
  status.kind = Value::Kind::kEnum;
  status.u = 2;
  status.s = "HEADING_UNVERIFIED";
  g.expected.push_back(to_json(status));
  const Value v = expect_round_trip("poise::msg::AttitudeEstimate",
                                    serialize<poise::msg::AttitudeEstimatePubSubType>(m), g);
  EXPECT_EQ(v.at("attitude_covariance.8")->d, m.attitude_covariance()[8]);
}

TEST(CdrDecode, GivenAFilledPoseEstimateWhenSerializedByFastcdrThenEveryFieldDecodes) {
  Leaves g;
  poise::msg::PoseEstimate m;
  g.header(m.header());
  m.sensor_id(g.s(1));
  m.filter_id(g.s(7));
  g.vec(m.position_m());
  g.vec(m.velocity_mps());
  g.quat(m.q_world_body());
  g.doubles(m.covariance());
  m.sources_fused(g.u32());
  expect_round_trip("poise::msg::PoseEstimate", serialize<poise::msg::PoseEstimatePubSubType>(m), g);
}

TEST(CdrDecode, GivenAFilledAltitudeEstimateWhenSerializedByFastcdrThenEveryFieldDecodes) {
  Leaves g;
  poise::msg::AltitudeEstimate m;
  g.header(m.header());
  m.sensor_id(g.s(3));
  m.filter_id(g.s(2));
  m.method(g.s(16));
  m.height_m(g.d());
  m.vertical_velocity_mps(g.d());
  m.vertical_accel_mps2(g.d());
  m.stationary(g.b());
  m.baro_valid(g.b());
  m.baro_height_m(g.d());
  m.reference_pressure_pa(g.d());
  expect_round_trip("poise::msg::AltitudeEstimate",
                    serialize<poise::msg::AltitudeEstimatePubSubType>(m), g);
}

TEST(CdrDecode, GivenAFilledFilterDiagnosticsWhenSerializedByFastcdrThenEveryFieldDecodes) {
  Leaves g;
  poise::msg::FilterDiagnostics m;
  g.header(m.header());
  m.sensor_id(g.s(9));
  m.component_name(g.s(11));
  for (std::size_t k = 0; k < 3; ++k) {  // 0, 1 and 6 (= bound) innovations
    poise::msg::SourceStatus st;
    st.source(g.s(4 + k));
    st.fresh(g.b());
    st.fused(g.b());
    st.reason(g.s(k == 2 ? 64 : k));
    const std::size_t n = k == 0 ? 0 : (k == 1 ? 1 : 6);
    for (std::size_t j = 0; j < n; ++j) {
      st.innovation().push_back(g.d());
    }
    for (std::size_t j = 0; j < n; ++j) {
      st.innovation_variance().push_back(g.d());
    }
    st.test_ratio(g.d());
    st.last_fused_stamp_ns(g.i64());
    st.fused_count(g.u64());
    st.rejected_count(g.u64());
    m.sources().push_back(st);
  }
  for (std::size_t k = 0; k < 64; ++k) {  // at the bound
    poise::msg::Counter c;
    c.name(g.s(k % 49));
    c.value(g.u64());
    m.counters().push_back(c);
  }
  poise::msg::Metric metric;
  metric.name(g.s(48));
  metric.value(g.d());
  metric.unit(g.s(16));
  m.metrics().push_back(metric);
  const Value v = expect_round_trip("poise::msg::FilterDiagnostics",
                                    serialize<poise::msg::FilterDiagnosticsPubSubType>(m), g);
  EXPECT_EQ(v.at("counters")->items.size(), 64U);
  EXPECT_EQ(v.at("sources.2.innovation.5")->d, m.sources()[2].innovation()[5]);
}

TEST(CdrDecode, GivenFilledTagDetectionsWhenSerializedByFastcdrThenEveryFieldDecodes) {
  Leaves g;
  poise::msg::TagDetections m;
  g.header(m.header());
  m.sensor_id(g.s(4));
  m.image_width_px(g.u32());
  m.image_height_px(g.u32());
  for (int k = 0; k < 2; ++k) {
    poise::msg::TagDetection t;
    t.id(g.i32());
    t.family(g.s(9));
    t.hamming(g.i32());
    t.decision_margin(g.d());
    for (auto& c : t.corners()) {
      c.x_px(g.d());
      c.y_px(g.d());
    }
    t.pose_valid(g.b());
    g.pose(t.pose_camera_tag());
    t.tag_size_m(g.d());
    t.reprojection_error_px(g.d());
    t.ambiguity_ratio(g.d());
    t.in_map(g.b());
    m.detections().push_back(t);
  }
  expect_round_trip("poise::msg::TagDetections", serialize<poise::msg::TagDetectionsPubSubType>(m),
                    g);
}

TEST(CdrDecode, GivenAFilledVisionPoseWhenSerializedByFastcdrThenEveryFieldDecodes) {
  Leaves g;
  poise::msg::VisionPose m;
  g.header(m.header());
  m.sensor_id(g.s(6));
  m.capture_stamp_ns(g.i64());
  g.pose(m.pose_world_camera());
  m.body_valid(g.b());
  g.pose(m.pose_world_body());
  g.doubles(m.covariance());
  m.reprojection_rms_px(g.d());
  for (int k = 0; k < 5; ++k) {
    m.tag_ids().push_back(g.i32());
  }
  expect_round_trip("poise::msg::VisionPose", serialize<poise::msg::VisionPosePubSubType>(m), g);
}

// ---------------------------------------------------------------------------------------------
// Output formats

TEST(CdrDecode, GivenNonFiniteAndSpecialValuesWhenPrintedThenJsonStaysValid) {
  poise::msg::VehicleInput m;
  m.header().stamp_ns(-5);
  m.header().frame_id("q\"\\\n\x01");
  m.speed_mps(std::numeric_limits<double>::quiet_NaN());
  const auto payload = serialize<poise::msg::VehicleInputPubSubType>(m);
  const Value v = decode(TypeTable::builtin(), "poise::msg::VehicleInput", payload);
  EXPECT_EQ(to_json(v),
            R"({"header":{"stamp_ns":-5,"seq":0,"frame_id":"q\"\\\n\u0001"},"sensor_id":"",)"
            R"("speed_mps":"NaN","speed_valid":false})");
  m.speed_mps(-std::numeric_limits<double>::infinity());
  EXPECT_NE(to_json(decode(TypeTable::builtin(), "poise::msg::VehicleInput",
                           serialize<poise::msg::VehicleInputPubSubType>(m)))
                .find(R"("speed_mps":"-Infinity")"),
            std::string::npos);
}

TEST(CdrDecode, GivenADecodedSampleWhenPrintedAsTextThenNestedStructsIndentAndListsInline) {
  poise::msg::VisionPose m;
  m.header().stamp_ns(42);
  m.sensor_id("cam0");
  m.tag_ids({3, 7});
  m.pose_world_body().position_m().x(1.5);
  const std::string text = to_text(decode(TypeTable::builtin(), "poise::msg::VisionPose",
                                          serialize<poise::msg::VisionPosePubSubType>(m)));
  EXPECT_EQ(text.rfind("header:\n  stamp_ns: 42\n  seq: 0\n  frame_id: \"\"\nsensor_id: \"cam0\"\n", 0), 0U)
      << text;
  EXPECT_NE(text.find("pose_world_body:\n  position_m:\n    x: 1.5\n"), std::string::npos) << text;
  EXPECT_NE(text.find("tag_ids: [3, 7]\n"), std::string::npos) << text;

  poise::msg::FilterDiagnostics d;
  poise::msg::Counter c;
  c.name("rejected_nan");
  c.value(4);
  d.counters({c, c});
  const std::string dt = to_text(decode(TypeTable::builtin(), "poise::msg::FilterDiagnostics",
                                        serialize<poise::msg::FilterDiagnosticsPubSubType>(d)));
  EXPECT_NE(dt.find("counters:\n  - name: \"rejected_nan\"\n    value: 4\n  - name:"), std::string::npos)
      << dt;
  EXPECT_NE(dt.find("sources: []\n"), std::string::npos) << dt;
}

// ---------------------------------------------------------------------------------------------
// Malformed payloads: an error, never a crash or an out-of-bounds read (run under ASan too).

std::vector<std::uint8_t> diagnostics_payload() {
  poise::msg::FilterDiagnostics m;
  m.sensor_id("imu0");
  poise::msg::SourceStatus st;
  st.source("accel");
  st.innovation({1.0, 2.0, 3.0});
  m.sources({st});
  return serialize<poise::msg::FilterDiagnosticsPubSubType>(m);
}

std::string decode_error(const std::vector<std::uint8_t>& payload,
                         const std::string& type = "poise::msg::FilterDiagnostics") {
  try {
    (void)decode(TypeTable::builtin(), type, payload);
  } catch (const DecodeError& e) {
    return e.what();
  }
  return "no error";
}

TEST(CdrDecode, GivenEveryTruncationOfAPayloadWhenDecodedThenEachIsAnError) {
  const auto full = diagnostics_payload();
  ASSERT_EQ(decode_error(full), "no error");
  for (std::size_t n = 0; n < full.size(); ++n) {
    const std::vector<std::uint8_t> cut(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(n));
    EXPECT_NE(decode_error(cut), "no error") << "truncated to " << n << " bytes";
  }
  EXPECT_NE(decode_error({full.begin(), full.begin() + 10}).find("truncated"), std::string::npos);
}

TEST(CdrDecode, GivenCorruptedFieldsWhenDecodedThenTheErrorNamesTheProblem) {
  const auto full = diagnostics_payload();
  auto bad = full;
  bad[1] = 0x03;  // PL_CDR_LE
  EXPECT_NE(decode_error(bad).find("unsupported encapsulation 0x0003"), std::string::npos);
  bad = full;
  bad[16] = 0xff;  // header.frame_id length (offset 4 + 12) far too long
  EXPECT_NE(decode_error(bad).find("header.frame_id"), std::string::npos) << decode_error(bad);
  bad = full;
  bad[16] = 66;  // 65 characters + NUL would exceed string<64>... and is not NUL-terminated here
  EXPECT_NE(decode_error(bad), "no error");
  bad = full;
  bad.insert(bad.end(), {1, 2, 3, 4});
  EXPECT_NE(decode_error(bad).find("unexpected bytes"), std::string::npos);
  bad = full;
  bad.insert(bad.end(), {0, 0, 0});  // up to 3 bytes of padding are fine
  EXPECT_EQ(decode_error(bad), "no error");

  // A boolean other than 0/1.
  poise::msg::VehicleInput vi;
  auto vp = serialize<poise::msg::VehicleInputPubSubType>(vi);
  vp.back() = 7;  // speed_valid is the last byte
  EXPECT_NE(decode_error(vp, "poise::msg::VehicleInput").find("boolean speed_valid"),
            std::string::npos);
  // A sequence count above its bound.
  poise::msg::VisionPose vpose;
  auto pp = serialize<poise::msg::VisionPosePubSubType>(vpose);
  pp[pp.size() - 4] = 65;  // tag_ids count is the last 4 bytes (empty sequence)
  EXPECT_NE(decode_error(pp, "poise::msg::VisionPose").find("more than its bound 64"),
            std::string::npos);
}

TEST(CdrDecode, GivenRandomBytesWhenDecodedAsEveryTypeThenNothingCrashes) {
  const unsigned seed = 20261122;
  std::mt19937 rng(seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const auto base = diagnostics_payload();
  int errors = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    auto p = base;
    const int flips = 1 + static_cast<int>(rng() % 8);
    for (int f = 0; f < flips; ++f) {
      p[rng() % p.size()] = static_cast<std::uint8_t>(rng());
    }
    p.resize(rng() % (p.size() + 8), 0);
    for (const auto& type : TypeTable::builtin().struct_names()) {
      try {
        (void)to_json(decode(TypeTable::builtin(), type, p));
      } catch (const DecodeError&) {
        ++errors;
      }
    }
  }
  EXPECT_GT(errors, 0);
}

TEST(CdrDecode, GivenABigEndianPayloadWhenDecodedThenValuesAreTheSame) {
  poise::msg::VehicleInput m;
  m.header().stamp_ns(0x0102030405060708);
  m.header().seq(77);
  m.sensor_id("imu0");
  m.speed_mps(2.5);
  eprosima::fastcdr::FastBuffer buffer;
  eprosima::fastcdr::Cdr ser(buffer, eprosima::fastcdr::Cdr::BIG_ENDIANNESS,
                             eprosima::fastcdr::Cdr::DDS_CDR);
  ser.serialize_encapsulation();
  m.serialize(ser);
  const std::vector<std::uint8_t> be(buffer.getBuffer(),
                                     buffer.getBuffer() + ser.getSerializedDataLength());
  ASSERT_EQ(be.size() > 1 ? int{be.at(1)} : -1, 0);  // CDR big endian
  const Value v = decode(TypeTable::builtin(), "poise::msg::VehicleInput", be);
  EXPECT_EQ(v.at("header.stamp_ns")->i, 0x0102030405060708);
  EXPECT_EQ(v.at("header.seq")->u, 77U);
  EXPECT_EQ(v.at("speed_mps")->d, 2.5);
  EXPECT_EQ(read_header_stamp_ns(be.data(), be.size()), 0x0102030405060708);
}

// The key bytes match what the generated type support hashes.
TEST(CdrDecode, GivenAKeyedSampleWhenItsKeyIsSerializedThenItMatchesFastddsgen) {
  poise::msg::ImuSample m;
  m.sensor_id("imu-left-7");
  m.header().seq(3);
  const auto payload = serialize<poise::msg::ImuSamplePubSubType>(m);
  const auto key = serialize_key_be(TypeTable::builtin(), "poise::msg::ImuSample",
                                    decode(TypeTable::builtin(), "poise::msg::ImuSample", payload));
  eprosima::fastcdr::FastBuffer buffer;
  eprosima::fastcdr::Cdr ser(buffer, eprosima::fastcdr::Cdr::BIG_ENDIANNESS);
  m.serializeKey(ser);
  const std::vector<std::uint8_t> expected(buffer.getBuffer(),
                                           buffer.getBuffer() + ser.getSerializedDataLength());
  EXPECT_EQ(key, expected);
}

}  // namespace
}  // namespace poise::schema
