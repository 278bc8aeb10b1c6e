// IDL schema layer: parsing, errors, flattening to a self-contained omgidl schema, sizes.
#include "poise/schema/idl_schema.h"

#include <gtest/gtest.h>

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/estimatesPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>
#include <poise/msg/visionPubSubTypes.h>
#include <poise/ros2/nav_msgsPubSubTypes.h>
#include <poise/ros2/sensor_msgsPubSubTypes.h>
#include <poise/ros2/tf2_msgsPubSubTypes.h>

#include <string>
#include <vector>

namespace poise::schema {
namespace {

const std::string kDir = POISE_IDL_DIR;

TEST(IdlSchema, GivenThePoiseIdlWhenLoadedThenEveryTopicTypeIsKnownWithItsKey) {
  const TypeTable table = TypeTable::from_directory(kDir);
  for (const char* name :
       {"poise::msg::ImuSample", "poise::msg::VehicleInput", "poise::msg::AttitudeEstimate",
        "poise::msg::PoseEstimate", "poise::msg::AltitudeEstimate", "poise::msg::FilterDiagnostics",
        "poise::msg::TagDetections", "poise::msg::VisionPose"}) {
    const StructDef* s = table.find_struct(name);
    ASSERT_NE(s, nullptr) << name;
    EXPECT_EQ(s->members.at(0).name, "header") << name;
    EXPECT_EQ(s->members.at(1).name, "sensor_id") << name;
    EXPECT_TRUE(s->members.at(1).key) << name;
    EXPECT_TRUE(s->has_key()) << name;
  }
  EXPECT_FALSE(table.get_struct("poise::msg::Header").has_key());
  EXPECT_NE(table.find_struct("::poise::msg::Header"), nullptr);
  EXPECT_EQ(table.find_struct("poise::msg::Nope"), nullptr);
  EXPECT_THROW((void)table.get_struct("poise::msg::Nope"), SchemaError);
}

TEST(IdlSchema, GivenTheEmbeddedIdlWhenLoadedThenItEqualsTheSourceDirectory) {
  const TypeTable embedded = TypeTable::from_sources(embedded_idl_sources());
  const TypeTable dir = TypeTable::from_directory(kDir);
  EXPECT_EQ(embedded.struct_names(), dir.struct_names());
  for (const auto& name : dir.struct_names()) {
    EXPECT_EQ(embedded.flatten(name), dir.flatten(name)) << name;
  }
}

TEST(IdlSchema, GivenMemberShapesWhenParsedThenBoundsArraysAndSequencesAreResolved) {
  const TypeTable& table = TypeTable::builtin();
  const StructDef& pose = table.get_struct("poise::msg::PoseEstimate");
  const Member& cov = pose.members.at(6);
  ASSERT_EQ(cov.name, "covariance");
  EXPECT_EQ(cov.type.kind, TypeSpec::Kind::kArray);
  EXPECT_EQ(cov.type.bound, 81U);
  EXPECT_EQ(cov.type.element->primitive, PrimitiveKind::kDouble);
  const StructDef& diag = table.get_struct("poise::msg::FilterDiagnostics");
  const Member& sources = diag.members.at(3);
  EXPECT_EQ(sources.type.kind, TypeSpec::Kind::kSequence);
  EXPECT_EQ(sources.type.bound, 16U);
  EXPECT_EQ(sources.type.element->name, "poise::msg::SourceStatus");
  const Member& id = diag.members.at(1);
  EXPECT_EQ(id.type.kind, TypeSpec::Kind::kString);
  EXPECT_EQ(id.type.bound, 64U);
}

// The flattened schema is self-contained: it parses on its own (no #include) into the same type.
TEST(IdlSchema, GivenEveryTopicTypeWhenFlattenedThenTheTextParsesAloneIntoTheSameTypes) {
  const TypeTable& table = TypeTable::builtin();
  for (const auto& name : table.struct_names()) {
    const std::string text = table.flatten(name);
    EXPECT_EQ(text.find('#'), std::string::npos) << name;
    const TypeTable alone = TypeTable::from_sources({{"flat.idl", text}});
    const StructDef& a = alone.get_struct(name);
    const StructDef& b = table.get_struct(name);
    ASSERT_EQ(a.members.size(), b.members.size()) << name;
    for (std::size_t k = 0; k < a.members.size(); ++k) {
      EXPECT_EQ(a.members[k].name, b.members[k].name);
      EXPECT_EQ(a.members[k].key, b.members[k].key);
    }
    EXPECT_EQ(alone.max_serialized_size(name), table.max_serialized_size(name)) << name;
    EXPECT_EQ(alone.flatten(name), text) << name;  // a fixed point
  }
}

TEST(IdlSchema, GivenImuSampleWhenFlattenedThenDependenciesComeFirstAndUnusedTypesAreLeftOut) {
  const std::string text = TypeTable::builtin().flatten("poise::msg::ImuSample");
  std::cout << text;
  const auto header = text.find("struct Header {");
  const auto vector3 = text.find("struct Vector3 {");
  const auto validity = text.find("struct ImuValidity {");
  const auto sample = text.find("struct ImuSample {");
  ASSERT_NE(header, std::string::npos);
  ASSERT_NE(sample, std::string::npos);
  EXPECT_LT(header, sample);
  EXPECT_LT(vector3, sample);
  EXPECT_LT(validity, sample);
  EXPECT_EQ(text.find("Quaternion"), std::string::npos);
  EXPECT_EQ(text.find("VehicleInput"), std::string::npos);
  EXPECT_NE(text.find("@key string<64> sensor_id;"), std::string::npos);
  EXPECT_EQ(text.rfind("module poise {", 0), 0U);
}

// Sizes agree with fastddsgen's generated type support (m_typeSize = max + padding to 4 + 4).
TEST(IdlSchema, GivenEveryTopicTypeWhenSizedThenMaxSizeMatchesTheGeneratedTypeSupport) {
  const TypeTable& table = TypeTable::builtin();
  const auto expect_size = [&table](const std::string& name, std::size_t generated_type_size,
                                    std::size_t generated_key_size) {
    std::size_t max = table.max_serialized_size(name);
    max += (4 - max % 4) % 4;
    EXPECT_EQ(max + 4, generated_type_size) << name;
    EXPECT_EQ(table.key_max_serialized_size(name), generated_key_size) << name;
  };
  expect_size("poise::msg::ImuSample", poise::msg::ImuSamplePubSubType().m_typeSize,
              poise::msg::ImuSample::getKeyMaxCdrSerializedSize());
  expect_size("poise::msg::VehicleInput", poise::msg::VehicleInputPubSubType().m_typeSize,
              poise::msg::VehicleInput::getKeyMaxCdrSerializedSize());
  expect_size("poise::msg::AttitudeEstimate", poise::msg::AttitudeEstimatePubSubType().m_typeSize,
              poise::msg::AttitudeEstimate::getKeyMaxCdrSerializedSize());
  expect_size("poise::msg::PoseEstimate", poise::msg::PoseEstimatePubSubType().m_typeSize,
              poise::msg::PoseEstimate::getKeyMaxCdrSerializedSize());
  expect_size("poise::msg::AltitudeEstimate", poise::msg::AltitudeEstimatePubSubType().m_typeSize,
              poise::msg::AltitudeEstimate::getKeyMaxCdrSerializedSize());
  expect_size("poise::msg::FilterDiagnostics",
              poise::msg::FilterDiagnosticsPubSubType().m_typeSize,
              poise::msg::FilterDiagnostics::getKeyMaxCdrSerializedSize());
  expect_size("poise::msg::TagDetections", poise::msg::TagDetectionsPubSubType().m_typeSize,
              poise::msg::TagDetections::getKeyMaxCdrSerializedSize());
  expect_size("poise::msg::VisionPose", poise::msg::VisionPosePubSubType().m_typeSize,
              poise::msg::VisionPose::getKeyMaxCdrSerializedSize());
}

// idl/ros2: the DDS names ROS 2 uses (pkg::msg::dds_::Name_), the .msg field order, and the same
// wire sizes as fastddsgen's type support of the same files (so `poise record` schemas match).
TEST(IdlSchema, GivenTheRos2IdlWhenLoadedThenTypesHaveRosDdsNamesFieldOrderAndGeneratedSizes) {
  const TypeTable& table = TypeTable::builtin();
  const auto names_of = [&table](const std::string& type) {
    std::vector<std::string> names;
    for (const auto& m : table.get_struct(type).members) {
      names.push_back(m.name);
    }
    return names;
  };
  using V = std::vector<std::string>;
  EXPECT_EQ(names_of("builtin_interfaces::msg::dds_::Time_"), (V{"sec", "nanosec"}));
  EXPECT_EQ(names_of("std_msgs::msg::dds_::Header_"), (V{"stamp", "frame_id"}));
  EXPECT_EQ(names_of("geometry_msgs::msg::dds_::Quaternion_"), (V{"x", "y", "z", "w"}));
  EXPECT_EQ(names_of("sensor_msgs::msg::dds_::Imu_"),
            (V{"header", "orientation", "orientation_covariance", "angular_velocity",
               "angular_velocity_covariance", "linear_acceleration",
               "linear_acceleration_covariance"}));
  EXPECT_EQ(names_of("sensor_msgs::msg::dds_::MagneticField_"),
            (V{"header", "magnetic_field", "magnetic_field_covariance"}));
  EXPECT_EQ(names_of("sensor_msgs::msg::dds_::FluidPressure_"), (V{"header", "fluid_pressure", "variance"}));
  EXPECT_EQ(names_of("sensor_msgs::msg::dds_::Temperature_"), (V{"header", "temperature", "variance"}));
  EXPECT_EQ(names_of("nav_msgs::msg::dds_::Odometry_"), (V{"header", "child_frame_id", "pose", "twist"}));
  EXPECT_EQ(names_of("geometry_msgs::msg::dds_::TransformStamped_"),
            (V{"header", "child_frame_id", "transform"}));
  EXPECT_EQ(names_of("geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"), (V{"header", "pose"}));
  const Member& transforms = table.get_struct("tf2_msgs::msg::dds_::TFMessage_").members.at(0);
  EXPECT_EQ(transforms.type.kind, TypeSpec::Kind::kSequence);
  EXPECT_EQ(transforms.type.bound, 0U);  // unbounded, as ROS's TransformStamped[]
  const auto expect_size = [&table](const std::string& name, std::size_t generated_type_size) {
    std::size_t max = table.max_serialized_size(name);
    max += (4 - max % 4) % 4;
    EXPECT_EQ(max + 4, generated_type_size) << name;
    EXPECT_FALSE(table.get_struct(name).has_key()) << name;  // ROS 2 topics are keyless
  };
  expect_size("sensor_msgs::msg::dds_::Imu_", sensor_msgs::msg::dds_::Imu_PubSubType().m_typeSize);
  expect_size("sensor_msgs::msg::dds_::MagneticField_",
              sensor_msgs::msg::dds_::MagneticField_PubSubType().m_typeSize);
  expect_size("sensor_msgs::msg::dds_::FluidPressure_",
              sensor_msgs::msg::dds_::FluidPressure_PubSubType().m_typeSize);
  expect_size("nav_msgs::msg::dds_::Odometry_", nav_msgs::msg::dds_::Odometry_PubSubType().m_typeSize);
  expect_size("tf2_msgs::msg::dds_::TFMessage_", tf2_msgs::msg::dds_::TFMessage_PubSubType().m_typeSize);
  EXPECT_EQ(sensor_msgs::msg::dds_::Imu_PubSubType().getName(), std::string("sensor_msgs::msg::dds_::Imu_"));
}

TEST(IdlSchema, GivenConstsEnumsAndNestedModulesWhenParsedThenTheyResolve) {
  const TypeTable t = TypeTable::from_sources({{"a.idl", R"(
    /* block
       comment */
    #pragma once
    module outer { const uint32 N = 3; const long M = N; const double PI = 3.14;
      enum Mode { OFF, ON, AUTO };
      module inner {
        struct P { unsigned long long big; short s; @key(TRUE) long long id; @key(FALSE) char c; };
        struct Q { P p[N][2]; sequence<sequence<octet, M>> raw; Mode mode; string name; };
      };
    };
    module outer { struct R { inner::Q q; ::outer::Mode m2; }; };
  )"}});
  EXPECT_EQ(t.integer_constant("outer::M"), 3);
  const StructDef& p = t.get_struct("outer::inner::P");
  EXPECT_EQ(p.members[0].type.primitive, PrimitiveKind::kUInt64);
  EXPECT_EQ(p.members[1].type.primitive, PrimitiveKind::kInt16);
  EXPECT_TRUE(p.members[2].key);
  EXPECT_FALSE(p.members[3].key);
  const StructDef& q = t.get_struct("outer::inner::Q");
  EXPECT_EQ(q.members[0].type.bound, 3U);
  EXPECT_EQ(q.members[0].type.element->bound, 2U);
  EXPECT_EQ(q.members[1].type.element->bound, 3U);
  EXPECT_EQ(q.members[2].type.kind, TypeSpec::Kind::kEnum);
  const std::string flat = t.flatten("outer::R");
  const TypeTable again = TypeTable::from_sources({{"flat.idl", flat}});
  EXPECT_EQ(again.flatten("outer::R"), flat) << flat;
  EXPECT_NE(flat.find("P p[3][2];"), std::string::npos) << flat;
  ASSERT_NE(t.find_enum("outer::Mode"), nullptr);
  EXPECT_EQ(t.find_enum("outer::Mode")->enumerators.size(), 3U);
}

TEST(IdlSchema, GivenBadIdlWhenParsedThenTheErrorNamesFileAndLine) {
  const auto error_of = [](const std::string& text) {
    try {
      (void)TypeTable::from_sources({{"bad.idl", text}});
    } catch (const SchemaError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of("module m {\n struct S { Unknown u; };\n};").find("bad.idl:2: unknown type 'Unknown'"),
            std::string::npos);
  EXPECT_NE(error_of("module m { union U switch(long) { case 1: long a; }; };").find("unsupported"),
            std::string::npos);
  EXPECT_NE(error_of("module m { struct S { long a; long a; }; };").find("declared twice"),
            std::string::npos);
  EXPECT_NE(error_of("module m { struct S { long a[0]; }; };").find("array dimension"),
            std::string::npos);
  EXPECT_NE(error_of("module m { struct S { long a; };").find("missing '}'"), std::string::npos);
  EXPECT_NE(error_of("/* open").find("unterminated"), std::string::npos);
  EXPECT_NE(error_of("#include \"missing.idl\"\n").find("'missing.idl' not found"),
            std::string::npos);
  EXPECT_NE(error_of("module m { struct S { sequence<long, X> a; }; };").find("unknown integer constant"),
            std::string::npos);
  EXPECT_NE(error_of("module m { enum E { A, @value(3) B }; };").find("@value"), std::string::npos);
  EXPECT_THROW((void)TypeTable::from_directory("/nonexistent-idl-dir"), SchemaError);
}

}  // namespace
}  // namespace poise::schema
