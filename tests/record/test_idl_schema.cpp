// Flattened omgidl schemas: self-contained, dependencies first, no preprocessor directives.
#include "poise/record/idl_schema.h"

#include <gtest/gtest.h>

namespace poise::record {
namespace {

TEST(IdlSchema, FlattenedTypeHasItsDependenciesFirstAndNoPreprocessorLines) {
  const auto text = flattened_idl("poise::msg::ImuSample");
  ASSERT_TRUE(text.has_value());
  const size_t header = text->find("struct Header");
  const size_t sample = text->find("struct ImuSample");
  ASSERT_NE(header, std::string::npos);
  ASSERT_NE(sample, std::string::npos);
  EXPECT_LT(header, sample);
  EXPECT_EQ(text->find("#include"), std::string::npos);
  EXPECT_EQ(text->find("\n#"), std::string::npos);
  // Only what ImuSample needs: not the estimates file.
  EXPECT_EQ(text->find("struct AttitudeEstimate"), std::string::npos);
}

TEST(IdlSchema, EveryPoiseTopicTypeIsFound) {
  for (const char* name :
       {"poise::msg::ImuSample", "poise::msg::VehicleInput", "poise::msg::TagDetections",
        "poise::msg::VisionPose", "poise::msg::AttitudeEstimate", "poise::msg::PoseEstimate",
        "poise::msg::AltitudeEstimate", "poise::msg::FilterDiagnostics"}) {
    EXPECT_TRUE(flattened_idl(name).has_value()) << name;
  }
}

TEST(IdlSchema, UnknownTypesAndWrongModulesAreNotFound) {
  EXPECT_FALSE(flattened_idl("poise::msg::NoSuchType").has_value());
  EXPECT_FALSE(flattened_idl("other::msg::ImuSample").has_value());
}

}  // namespace
}  // namespace poise::record
