// Hostile configuration files and command lines (issue 19, item 9). Oracle: the documented
// contract of each loader: refuse, and name the file, the key (and line) or the option.
#include "poise/camera/intrinsics.h"
#include "poise/camera/tag_map.h"
#include "poise/core/yaml_params.h"
#include "poise/dds/topics.h"
#include "poise/imu/config.h"
#include "poise/imu/serial_port.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/runtime/host.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <functional>
#include <string>

namespace poise {
namespace {

std::string write_file(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

/// Runs `f`, which must throw; returns the message.
std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  ADD_FAILURE() << "accepted";
  return {};
}

#define EXPECT_HAS(haystack, needle) EXPECT_NE((haystack).find(needle), std::string::npos) << (haystack)

TEST(HostileYaml, GivenADuplicateKeyAnywhereWhenParsedThenTheKeyPathAndBothLinesAreNamed) {
  EXPECT_HAS(error_of([] { (void)parse_yaml("a: 1\nb: 2\na: 3\n", "f.yaml"); }),
             "f.yaml:3: key 'a' is given twice (first on line 1)");
  EXPECT_HAS(error_of([] { (void)parse_yaml("top:\n  x: 1\n  y: 2\n  x: 1\n", "f.yaml"); }),
             "f.yaml:4: key 'top.x' is given twice (first on line 2)");
  EXPECT_HAS(error_of([] { (void)parse_yaml("list:\n  - {id: 1, id: 2}\n", "f.yaml"); }),
             "key 'list[0].id' is given twice");
  EXPECT_NO_THROW((void)parse_yaml("a: {x: 1}\nb: {x: 1}\n", "f.yaml"));  // same key in two maps
}

TEST(HostileYaml, GivenANonFiniteNumberWhenParsedThenRefusedNamingTheKeyButAQuotedStringIsKept) {
  for (const char* v : {".inf", "-.inf", "+.INF", ".nan", ".NaN"}) {
    EXPECT_HAS(error_of([v] { (void)parse_yaml(std::string("outer:\n  mag_norm_tol: ") + v + "\n", "p.yaml"); }),
               std::string("p.yaml:2: 'outer.mag_norm_tol' is ") + v + ": values must be finite numbers");
  }
  EXPECT_EQ(parse_yaml("name: \".inf\"\n", "p.yaml")["name"].as<std::string>(), ".inf");
  const std::string path = write_file("inf_file.yaml", "k: [1, .nan]\n");
  EXPECT_HAS(error_of([&] { (void)load_yaml_file(path, "test file"); }), path + ":1: 'k[1]' is .nan");
}

TEST(HostileYaml, GivenEveryLoaderWhenAKeyIsDuplicatedOrNonFiniteThenItRefusesNamingTheFileAndKey) {
  // filter parameters
  const std::string kf = write_file("kf_dup.yaml", "parallel_kf:\n  mag_norm_tol: 0.1\n  mag_norm_tol: 0.2\n");
  EXPECT_HAS(error_of([&] { (void)load_parallel_kf_params(kf); }),
             kf + ":3: key 'parallel_kf.mag_norm_tol' is given twice (first on line 2)");
  const std::string kf_inf = write_file("kf_inf.yaml", "parallel_kf:\n  mag_norm_tol: .inf\n");
  EXPECT_HAS(error_of([&] { (void)load_parallel_kf_params(kf_inf); }), "'parallel_kf.mag_norm_tol' is .inf");
  // host file
  const std::string host = write_file("host_dup.yaml",
                                      "components:\n  - type: parallel_kf\n    name: a\n    name: b\n");
  EXPECT_HAS(error_of([&] { (void)runtime::load_host_file(host); }),
             host + ":4: key 'components[0].name' is given twice");
  // driver configuration
  EXPECT_HAS(error_of([] { (void)imu::parse_driver_config("serial:\n  baud: 115200\n  baud: 9600\n", "drv.yaml"); }),
             "drv.yaml:3: key 'serial.baud' is given twice");
  // camera intrinsics (ROS camera_info)
  EXPECT_HAS(error_of([] {
               (void)camera::parse_intrinsics(
                   "image_width: 640\nimage_height: 480\nimage_width: 320\ncamera_matrix:\n  data: [500, 0, 320, 0, "
                   "500, 240, 0, 0, 1]\n",
                   "cam.yaml");
             }),
             "cam.yaml:3: key 'image_width' is given twice");
  // tag map
  EXPECT_HAS(error_of([] {
               (void)camera::parse_tag_map(
                   "tags:\n  - {id: 1, size_m: 0.1, position_m: [0, 0, 0], position_m: [1, 0, 0], rpy_deg: [0, 0, 0]}\n",
                   "map.yaml");
             }),
             "map.yaml:2: key 'tags[0].position_m' is given twice");
}

TEST(HostileConfig, GivenAHostFileWithATopicThatIsNotAStringWhenLoadedThenTheFileAndTopicAreNamed) {
  const std::string host = write_file("host_topics.yaml", "topics: {imu: [1, 2]}\ncomponents:\n  - type: parallel_kf\n");
  EXPECT_HAS(error_of([&] { (void)runtime::load_host_file(host); }), host + ": topics.imu must be a topic name");
  const std::string comp = write_file("host_type.yaml", "components:\n  - type: [parallel_kf]\n");
  EXPECT_HAS(error_of([&] { (void)runtime::load_host_file(comp); }), comp + ": components[0]: ");
}

TEST(HostileConfig, GivenANameLongerThanTheSensorIdBoundWhenUsedThenRefusedNeverCut) {
  const std::string ok(dds::kMaxSensorIdLength, 'a');
  EXPECT_EQ(dds::checked_sensor_id(ok, "x"), ok);
  const std::string too_long(dds::kMaxSensorIdLength + 1, 'a');
  EXPECT_HAS(error_of([&] { (void)dds::checked_sensor_id(too_long, "where"); }),
             "where: instance name '" + too_long + "' has 65 characters");
  EXPECT_THROW((void)dds::checked_sensor_id("", "x"), std::invalid_argument);
  // through a host file: refused before any DDS entity exists
  const std::string host = write_file("host_long.yaml", "components:\n  - type: parallel_kf\n    name: " + too_long + "\n");
  const auto r = testing::run({testing::bin("poise"), "run", host}, std::chrono::seconds(30));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_HAS(r.output, "has 65 characters");
}

TEST(HostileConfig, GivenTagIdsBeyondTheFamilyWhenTheMapIsLoadedThenRefused) {
  const std::string entry = ", size_m: 0.1, position_m: [0, 0, 0], rpy_deg: [0, 0, 0]}\n";
  // tag36h11 has 587 codes (ids 0..586); tag16h5 has 30
  EXPECT_NO_THROW((void)camera::parse_tag_map("family: tag36h11\ntags:\n  - {id: 586" + entry, "m.yaml"));
  EXPECT_HAS(error_of([&] { (void)camera::parse_tag_map("family: tag36h11\ntags:\n  - {id: 587" + entry, "m.yaml"); }),
             "m.yaml: tag id 587 does not exist in tag36h11 (ids 0..586)");
  const camera::TagMap no_family = camera::parse_tag_map("tags:\n  - {id: 40" + entry, "m.yaml");
  EXPECT_HAS(error_of([&] { camera::check_tag_map_family(no_family, "tag16h5", "m.yaml"); }),
             "tag id 40 does not exist in tag16h5 (ids 0..29)");
  EXPECT_NO_THROW(camera::check_tag_map_family(no_family, "tag36h11", "m.yaml"));
}

TEST(HostileConfig, GivenAnIntrinsicsFileWithAnAbsurdResolutionWhenLoadedThenRefusedNamingTheFile) {
  const std::string k = "camera_matrix:\n  data: [500, 0, 320, 0, 500, 240, 0, 0, 1]\n";
  EXPECT_HAS(error_of([&] { (void)camera::parse_intrinsics("image_width: 2000000000\nimage_height: 480\n" + k, "c.yaml"); }),
             "c.yaml: image_width/image_height 2000000000x480 exceed 32768 px");
}

TEST(HostileConfig, GivenARegularFileOrADirectoryAsThePortWhenTheDriverStartsThenAClearErrorNotRetriedForever) {
  const std::string file = write_file("not_a_port", "hello\n");
  EXPECT_HAS(error_of([&] { imu::check_serial_path(file); }), file + " is a regular file, not a serial device");
  EXPECT_HAS(error_of([] { imu::check_serial_path("/tmp"); }), "/tmp is a directory, not a serial device");
  EXPECT_NO_THROW(imu::check_serial_path("/nonexistent/ttyUSB9"));  // may be plugged in later
  for (const std::string& port : {file, std::string("/tmp")}) {
    const auto r = testing::run({testing::bin("poise"), "imu", "--port", port, "--duration", "20"},
                                std::chrono::seconds(15));
    EXPECT_EQ(r.exit_code, 1) << r.output;  // not -1: it did not wait out the timeout
    EXPECT_HAS(r.output, "not a serial device");
  }
}

TEST(HostileCli, GivenAnUnknownSubcommandOrOptionWhenRunThenItIsNamed) {
  const auto sub = testing::run({testing::bin("poise"), "nosuchcmd"}, std::chrono::seconds(10));
  EXPECT_EQ(sub.exit_code, 2);
  EXPECT_HAS(sub.output, "unknown subcommand 'nosuchcmd'");
  const auto nested = testing::run({testing::bin("poise"), "eval", "nosuch"}, std::chrono::seconds(10));
  EXPECT_HAS(nested.output, "'poise eval': unknown subcommand 'nosuch' (known: broad)");
  const auto opt = testing::run({testing::bin("poise"), "eval", "--bogus"}, std::chrono::seconds(10));
  EXPECT_EQ(opt.exit_code, 2);
  EXPECT_HAS(opt.output, "unknown option '--bogus'");
  const auto leaf = testing::run({testing::bin("poise"), "parallel-kf", "--bogus"}, std::chrono::seconds(10));
  EXPECT_EQ(leaf.exit_code, 2);
  EXPECT_HAS(leaf.output, "--bogus");
}

TEST(HostileCli, GivenANonFiniteNumberForAnyFloatingPointOptionWhenRunThenRefusedBeforeRunning) {
  for (const char* v : {"nan", "inf", "-inf", "NaN", "infinity"}) {
    const auto r = testing::run({testing::bin("poise"), "parallel-kf", "--duration", v}, std::chrono::seconds(10));
    EXPECT_EQ(r.exit_code, 2) << v << ": " << r.output;  // a usage error, not a run
    // the option and the value are named (an option with a range check may refuse it first)
    EXPECT_HAS(r.output, "--duration: ");
    EXPECT_HAS(r.output, v);
  }
  const auto sim = testing::run({testing::bin("poise"), "sim-imu", "--link", ::testing::TempDir() + "/l", "--duration", "nan"},
                                std::chrono::seconds(10));
  EXPECT_EQ(sim.exit_code, 2) << sim.output;
  EXPECT_HAS(sim.output, "--duration: 'nan' is not a finite number");
}

}  // namespace
}  // namespace poise
