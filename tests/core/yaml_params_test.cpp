// The one loader shape (YamlParamReader) and the one unknown-key check (poise/core/yaml_params.h).
// Oracle: the documented contract of each call.
#include "poise/core/yaml_params.h"

#include "poise/testing/param_errors.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace poise {
namespace {

enum class Colour { kRed, kBlue };
const char* to_string(Colour c) { return c == Colour::kRed ? "red" : "blue"; }

struct Example {
  double gain = 1.0;
  double dip_deg = 60.0;
  int count = 3;
  bool on = false;
  std::string name = "a";
  Eigen::Vector3d v{1.0, 2.0, 3.0};
  Colour colour = Colour::kRed;
  double inner_x = 0.5;
};

/// Reads an Example from YAML text the way every loader does; returns the error message or "".
std::string load(const std::string& text, Example& e) {
  return testing::error_message([&] {
    YamlParamReader r(parse_yaml(text, "f.yaml"), "f.yaml");
    r.get("gain", e.gain);
    r.get_nullable("dip_deg", e.dip_deg);
    r.get_in("count", e.count, 1, 10);
    r.get("on", e.on);
    r.get("name", e.name);
    r.get("v", e.v);
    r.get_enum("colour", e.colour, {Colour::kRed, Colour::kBlue});
    YamlParamReader inner = r.child("inner");
    inner.get("x", e.inner_x);
    inner.finish();
    r.finish();
  });
}

TEST(YamlParamReader, GivenAnEmptyDocumentThenEveryDefaultIsKept) {
  for (const char* text : {"", "# only a comment\n", "{}"}) {
    Example e;
    ASSERT_EQ(load(text, e), "") << text;
    EXPECT_EQ(e.gain, 1.0);
    EXPECT_EQ(e.count, 3);
    EXPECT_EQ(e.v, Eigen::Vector3d(1.0, 2.0, 3.0));
    EXPECT_EQ(e.inner_x, 0.5);
  }
}

TEST(YamlParamReader, GivenEveryKindOfKeyThenEachIsReadAndNullIsRefusedOrMeansNaNWhereDocumented) {
  Example e;
  ASSERT_EQ(load("gain: 2.5\ndip_deg: ~\ncount: 7\non: true\nname: b\nv: [4, 5, 6]\ncolour: blue\ninner: {x: 9}\n", e),
            "");
  EXPECT_EQ(e.gain, 2.5);
  EXPECT_TRUE(std::isnan(e.dip_deg));  // get_nullable: null = NaN (learn it)
  EXPECT_EQ(e.count, 7);
  EXPECT_TRUE(e.on);
  EXPECT_EQ(e.name, "b");
  EXPECT_EQ(e.v, Eigen::Vector3d(4.0, 5.0, 6.0));
  EXPECT_EQ(e.colour, Colour::kBlue);
  EXPECT_EQ(e.inner_x, 9.0);
  Example d;
  // get: a key without a value is refused (it kept the default silently before issue 33)
  EXPECT_EQ(load("gain: ~\n", d), "f.yaml: gain has no value (empty or ~): give one, or leave the key out for the default");
  EXPECT_EQ(load("inner:\n  x:\n", d), "f.yaml: inner.x has no value (empty or ~): give one, or leave the key out for the default");
  EXPECT_EQ(d.gain, 1.0);
}

TEST(YamlParamReader, GivenADottedKeyThenItIsTheSameAsTheNestedOneAndBothAtOnceAreRefused) {
  Example dotted;
  ASSERT_EQ(load("inner.x: 4\n", dotted), "");
  EXPECT_EQ(dotted.inner_x, 4.0);
  Example both;
  EXPECT_EQ(load("inner: {x: 1}\ninner.x: 2\n", both), "f.yaml: inner.x is given twice");
}

TEST(YamlParamReader, GivenAnUnknownKeyAtAnyLevelThenTheOneMessageListsTheKeysReadThereInOrder) {
  Example e;
  EXPECT_EQ(load("gian: 2\n", e),
            "f.yaml: unknown key 'gian' (known: gain, dip_deg, count, on, name, v, colour, inner)");
  EXPECT_EQ(load("inner: {y: 2}\n", e), "f.yaml: unknown key 'inner.y' (known: x)");
  EXPECT_EQ(load("inner.y: 2\n", e), "f.yaml: unknown key 'inner.y' (known: x)");
}

TEST(YamlParamReader, GivenAWrongTypeOrAValueOutOfRangeThenTheMessageNamesTheKeyAndWhatItMustBe) {
  Example e;
  EXPECT_EQ(load("gain: fast\n", e), "f.yaml: gain must be a number");
  EXPECT_EQ(load("count: 2.5\n", e), "f.yaml: count must be an integer");
  EXPECT_EQ(load("count: 11\n", e), "f.yaml: count must be in [1, 10], got 11");
  EXPECT_EQ(load("on: maybe\n", e), "f.yaml: on must be true or false");
  EXPECT_EQ(load("v: [1, 2]\n", e), "f.yaml: v must be a list of 3 numbers");
  EXPECT_EQ(load("colour: green\n", e), "f.yaml: colour must be one of red, blue (got 'green')");
  EXPECT_EQ(load("inner: 3\n", e), "f.yaml: inner must be a mapping");
  EXPECT_EQ(load("[1, 2]\n", e), "f.yaml: the document must be a mapping");
}

TEST(CheckKnownKeys, GivenAMappingThenOnlyItsUnknownKeysAreRefusedWithTheOneMessage) {
  const YAML::Node m = parse_yaml("a: 1\nb: {c: 2}\n", "f.yaml");
  EXPECT_NO_THROW(check_known_keys(m, {"a", "b"}, "f.yaml"));
  EXPECT_NO_THROW(check_known_keys(m["b"], {"c"}, "f.yaml", "b."));
  EXPECT_NO_THROW(check_known_keys(YAML::Node(), {"a"}, "f.yaml"));  // null: no keys
  EXPECT_EQ(testing::error_message([&] { check_known_keys(m, {"a"}, "f.yaml"); }),
            "f.yaml: unknown key 'b' (known: a)");
  EXPECT_EQ(testing::error_message([&] { check_known_keys(m["b"], {"d", "e"}, "f.yaml", "b."); }),
            "f.yaml: unknown key 'b.c' (known: d, e)");
  EXPECT_EQ(testing::error_message([&] { check_known_keys(m["a"], {"x"}, "f.yaml", "a."); }),
            "f.yaml: a must be a mapping");
  EXPECT_EQ(unknown_key_message("w", "k", {"a", "b"}), "w: unknown key 'k' (known: a, b)");
}

}  // namespace
}  // namespace poise
