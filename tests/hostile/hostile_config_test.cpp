// Hostile configuration files and command lines (issue 19, item 9). Oracle: the documented
// contract of each loader: refuse, and name the file, the key (and line) or the option.
#include "poise/altitude/altitude_filter.h"
#include "poise/camera/camera_node.h"
#include "poise/camera/intrinsics.h"
#include "poise/camera/pipeline.h"
#include "poise/camera/tag_map.h"
#include "poise/core/north_yaml.h"
#include "poise/core/yaml_params.h"
#include "poise/dds/topics.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/imu/config.h"
#include "poise/imu/faults.h"
#include "poise/imu/imu_driver_node.h"
#include "poise/imu/serial_port.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/ros2_bridge/bridge.h"
#include "poise/runtime/host.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/testing/param_errors.h"
#include "poise/testing/testing.h"
#include "poise/vehicle/vehicle_estimator.h"

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

namespace poise {
namespace {

std::string write_file(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

/// A component `type` named `<type>0` with `params` (YAML), as a host file's first entry gives it.
runtime::ComponentSpec spec(const std::string& type, const std::string& params) {
  runtime::ComponentSpec c;
  c.type = type;
  c.name = type + "0";
  c.params = parse_yaml(params, "params");
  c.origin = "host.yaml: components[0] (" + c.name + ")";
  return c;
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

// Issue 30: one helper for unknown keys. Every loader, given a key it does not read (a typo),
// refuses it with the one message "<file or component>: unknown key '<key as spelled from the
// document>' (known: <what is allowed there>)". Oracle: the documented shape and the keys each
// loader documents.
TEST(HostileConfig, GivenAnUnknownKeyInAnyLoaderWhenLoadedThenTheOneMessageNamesTheFileTheKeyAndWhatIsAllowed) {
  struct Case {
    const char* loader;
    std::function<std::string()> error;  // the loader's message for a file with one unknown key
    std::string where;
    std::string key;
    std::vector<std::string> allowed;  // some of the keys the message must list
  };
  const std::string kf = write_file("kf_unknown.yaml", "parallel_kf:\n  mag_norm_toll: 0.1\n");
  const std::string kf_tilt = write_file("kf_tilt.yaml", "parallel_kf:\n  tilt:\n    c_aa: 0.1\n");
  const std::string kf_dotted = write_file("kf_dotted.yaml", "tilt.c_aa: 0.1\n");
  const std::string gn = write_file("gn_unknown.yaml", "gauss_newton:\n  max_iteration: 3\n");
  const std::string ekf = write_file("ekf_unknown.yaml", "selective_ekf:\n  gauss_newton: {tolerance: 1}\n");
  const std::string alt = write_file("alt_unknown.yaml", "cf:\n  sigma_bar_m: 1\n");
  const std::string veh = write_file("veh_unknown.yaml", "ekf:\n  r_mag: [1, 1, 1]\n");
  const std::string host_top = write_file("host_unknown.yaml", "domian: 3\ncomponents: [{type: parallel_kf}]\n");
  const std::string host_entry = write_file("host_entry.yaml", "components:\n  - {type: parallel_kf, parms: {}}\n");
  const std::string host_topics = write_file("host_topic.yaml", "topics: {imus: x}\ncomponents: [{type: parallel_kf}]\n");
  const std::string host_rt = write_file("host_rt.yaml", "realtime: {prio: 5}\ncomponents: [{type: parallel_kf}]\n");
  const auto msg = [](auto f) { return [f] { return testing::error_message(f); }; };
  const std::vector<Case> cases = {
      {"parallel_kf", msg([&] { (void)load_parallel_kf_params(kf); }), kf, "parallel_kf.mag_norm_toll",
       {"preset", "tilt", "mag_norm_tol", "limits", "use_magnetometer"}},
      {"parallel_kf tilt", msg([&] { (void)load_parallel_kf_params(kf_tilt); }), kf_tilt, "parallel_kf.tilt.c_aa",
       {"sigma_gyro_rps", "c_a", "gravity_mps2"}},
      {"parallel_kf dotted", msg([&] { (void)load_parallel_kf_params(kf_dotted); }), kf_dotted, "tilt.c_aa", {"c_a"}},
      {"gauss_newton", msg([&] { (void)load_gauss_newton_params(gn); }), gn, "gauss_newton.max_iteration",
       {"max_iterations", "dip_deg", "use_magnetometer"}},
      {"selective_ekf", msg([&] { (void)load_selective_ekf_params(ekf); }), ekf,
       "selective_ekf.gauss_newton.tolerance", {"max_iterations", "tolerance_rad"}},
      {"altitude", msg([&] { (void)load_altitude_params(alt); }), alt, "cf.sigma_bar_m", {"gains", "sigma_baro_m"}},
      {"vehicle", msg([&] { (void)load_vehicle_params(veh); }), veh, "ekf.r_mag", {"r_mag_ut2"}},
      {"imu driver", msg([] { (void)imu::parse_driver_config("clock:\n  blocks: 1\n", "drv.yaml"); }), "drv.yaml",
       "clock.blocks", {"block_s", "window_blocks"}},
      {"camera", msg([] { (void)camera::parse_camera_config("detector: {decimat: 2}\n", "cam.yaml"); }), "cam.yaml",
       "detector.decimat", {"decimate", "threads"}},
      {"host file", msg([&] { (void)runtime::load_host_file(host_top); }), host_top, "domian", {"domain", "components"}},
      {"host component", msg([&] { (void)runtime::load_host_file(host_entry); }), host_entry, "components[0].parms",
       {"type", "params"}},
      {"host topics", msg([&] { (void)runtime::load_host_file(host_topics); }), host_topics, "topics.imus",
       {"imu", "diagnostics"}},
      {"host realtime", msg([&] { (void)runtime::load_host_file(host_rt); }), host_rt, "realtime.prio",
       {"priority", "cpus", "lock_memory"}},
      {"imu_driver component", msg([] { (void)imu::imu_node_options(spec("imu_driver", "{port: /dev/x, bogus: 1}")); }),
       "host.yaml: components[0] (imu_driver0): imu_driver", "bogus", {"port", "config_file", "serial", "calibration"}},
      {"camera component", msg([] { (void)camera::camera_node_options(spec("camera", "{sorce: x}")); }),
       "host.yaml: components[0] (camera0): camera", "sorce", {"source", "intrinsics_file", "pace"}},
      {"ros2_bridge component", msg([] { (void)ros2::parse_bridge_config(parse_yaml("out: {attitud: [a]}", "p"), "o"); }),
       "o: ros2_bridge", "out.attitud", {"attitude", "tf"}},
      {"north keys", msg([] { (void)read_north_params(parse_yaml("location: {lat: 1, lon_deg: 2}", "p")); }), "north",
       "location.lat", {"lat_deg", "lon_deg", "alt_m"}},
      {"fault spec", msg([] { (void)imu::FaultSpec::parse("bogus=1"); }), "fault spec", "bogus", {"drop", "seed"}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.loader);
    const std::string message = c.error();
    std::printf("%-22s %s\n", c.loader, message.c_str());
    testing::expect_unknown_key_message(message, c.where, c.key, c.allowed);
  }
}

// Issue 33: a YAML alias (*name) is a shared node, so a self-reference (`&c [ {params: *c} ]`) is a
// cycle every tree walk follows forever (SIGSEGV) and nine lines of aliases make 9^9 nodes (a
// minute of CPU). Every loader reads YAML through parse_yaml(), which refuses an alias from the
// parser's events before a node is built. Oracle: the documented message names the file, the line
// and the alias.
TEST(HostileYaml, GivenAnAliasInAnyLoaderWhenLoadedThenRefusedNamingTheFileLineAndAlias) {
  std::string bomb = "a: &a [x, x, x, x, x, x, x, x, x]\n";
  for (char c = 'b'; c <= 'i'; ++c) {
    const char prev = static_cast<char>(c - 1);
    bomb += std::string(1, c) + ": &" + c + " [";
    for (int i = 0; i < 9; ++i) bomb += std::string(i ? ", " : "") + "*" + prev;
    bomb += "]\n";
  }
  const std::string cycle_host = write_file("alias_host.yaml", "components: &c [ {type: parallel_kf, params: *c} ]\n");
  const std::string rt_host = write_file("alias_rt.yaml", "realtime: &r {priority: *r}\ncomponents: [{type: parallel_kf}]\n");
  const std::string topics_host = write_file("alias_topics.yaml", "topics: {imu: &t imu, diagnostics: *t}\n"
                                                                  "components: [{type: parallel_kf}]\n");
  const std::string kf = write_file("alias_bomb.yaml", "parallel_kf:\n" + bomb);  // the alias on line 3
  const std::string gn = write_file("alias_gn.yaml", "gauss_newton: {max_iterations: &n 3, dip_deg: *n}\n");
  const std::string ekf = write_file("alias_ekf.yaml", "selective_ekf: &s {gauss_newton: *s}\n");
  const std::string alt = write_file("alias_alt.yaml", "cf: &c {gains: *c}\n");
  const std::string veh = write_file("alias_veh.yaml", "ekf: &e {r_mag_ut2: *e}\n");
  struct Case {
    const char* loader;
    std::function<void()> load;
    std::string where;  // "<file>:<line>: the alias *<name>"
  };
  const std::vector<Case> cases = {
      {"host components", [&] { (void)runtime::load_host_file(cycle_host); }, cycle_host + ":1: the alias *c"},
      {"host realtime", [&] { (void)runtime::load_host_file(rt_host); }, rt_host + ":1: the alias *r"},
      {"host topics", [&] { (void)runtime::load_host_file(topics_host); }, topics_host + ":1: the alias *t"},
      {"parallel_kf bomb", [&] { (void)load_parallel_kf_params(kf); }, kf + ":3: the alias *a"},
      {"gauss_newton", [&] { (void)load_gauss_newton_params(gn); }, gn + ":1: the alias *n"},
      {"selective_ekf", [&] { (void)load_selective_ekf_params(ekf); }, ekf + ":1: the alias *s"},
      {"altitude", [&] { (void)load_altitude_params(alt); }, alt + ":1: the alias *c"},
      {"vehicle", [&] { (void)load_vehicle_params(veh); }, veh + ":1: the alias *e"},
      {"imu driver", [] { (void)imu::parse_driver_config("serial: &s {baud: *s}\n", "drv.yaml"); }, "drv.yaml:1: the alias *s"},
      {"camera", [] { (void)camera::parse_camera_config("detector: &d {threads: *d}\n", "cam.yaml"); },
       "cam.yaml:1: the alias *d"},
      {"tag map", [] { (void)camera::parse_tag_map("tags: &t [*t]\n", "map.yaml"); }, "map.yaml:1: the alias *t"},
      {"intrinsics", [] { (void)camera::parse_intrinsics("image_width: &w 640\nimage_height: *w\n", "c.yaml"); },
       "c.yaml:2: the alias *w"},
      {"--set value", [] { (void)parse_yaml("&a [*a]", "--set parallel_kf.filter_file=&a [*a]"); },
       "--set parallel_kf.filter_file=&a [*a]:1: the alias *a"},
      {"north --set", [] { (void)read_north_params(parse_yaml("{location: &a {lat_deg: *a, lon_deg: 0}}", "--set")); },
       "--set:1: the alias *a"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.loader);
    const std::string message = error_of(c.load);
    EXPECT_HAS(message, c.where + " is not accepted: poise reads no YAML anchors or aliases");
  }
  // an anchor nothing refers to is harmless and still reads
  EXPECT_EQ(parse_yaml("a: &x 1\n", "f.yaml")["a"].as<int>(), 1);
}

// The same through the command line, as the issue ran them: an exit with the message within a
// bounded wait, not a crash (SIGSEGV) or a minute of CPU.
TEST(HostileYaml, GivenTheIssuesAliasInputsWhenPoiseRunsThemThenItExitsWithTheMessage) {
  const std::string cycle_host = write_file("alias_cli_host.yaml", "components: &c [ {type: parallel_kf, params: *c} ]\n");
  const std::string host = write_file("alias_cli_ok.yaml", "components:\n  - {type: parallel_kf, name: parallel_kf}\n");
  std::string bomb = "a: &a [x, x, x, x, x, x, x, x, x]\n";
  for (char c = 'b'; c <= 'i'; ++c) {
    bomb += std::string(1, c) + ": &" + c + " [*" + static_cast<char>(c - 1) + ", *" + static_cast<char>(c - 1) +
            ", *" + static_cast<char>(c - 1) + "]\n";
  }
  const std::string bomb_file = write_file("alias_cli_bomb.yaml", bomb);
  const std::vector<std::pair<std::vector<std::string>, std::string>> runs = {
      {{testing::bin("poise"), "run", cycle_host}, cycle_host + ":1: the alias *c is not accepted"},
      {{testing::bin("poise"), "run", host, "--set", "parallel_kf.filter_file=&a [*a]"}, ":1: the alias *a is not accepted"},
      {{testing::bin("poise"), "run", host, "--set", "parallel_kf.filter_file=" + bomb_file},
       bomb_file + ":2: the alias *a is not accepted"},
      {{testing::bin("poise"), "parallel-kf", "--config", bomb_file, "--duration", "1"},
       bomb_file + ":2: the alias *a is not accepted"},
  };
  for (const auto& [argv, expected] : runs) {
    SCOPED_TRACE(argv.back());
    const auto r = testing::run(argv, std::chrono::seconds(20));
    // 1: a setup error, 2: a usage error (--set's value); -1 would be the timeout, a signal another value
    EXPECT_TRUE(r.exit_code == 1 || r.exit_code == 2) << r.exit_code << ": " << r.output;
    EXPECT_HAS(r.output, expected);
  }
}

TEST(HostileYaml, GivenNestingTooDeepTextTooLargeOrAFifoWhenLoadedThenRefusedBeforeParsing) {
  const std::string deep = std::string(static_cast<std::size_t>(kMaxYamlDepth) + 1, '[') +
                           std::string(static_cast<std::size_t>(kMaxYamlDepth) + 1, ']');
  EXPECT_HAS(error_of([&] { (void)parse_yaml(deep, "deep.yaml"); }), "deep.yaml:1: nested more than 32 levels deep");
  const std::string ok_depth = std::string(static_cast<std::size_t>(kMaxYamlDepth), '[') +
                               std::string(static_cast<std::size_t>(kMaxYamlDepth), ']');
  EXPECT_NO_THROW((void)parse_yaml(ok_depth, "deep.yaml"));
  const std::string huge = write_file("huge.yaml", "# " + std::string(kMaxYamlBytes, 'x') + "\n");
  EXPECT_HAS(error_of([&] { (void)load_parallel_kf_params(huge); }),
             huge + ": " + std::to_string(kMaxYamlBytes + 3) + " bytes: more than the 1048576 a configuration may hold");
  const std::string fifo = ::testing::TempDir() + "/filter_fifo.yaml";
  std::remove(fifo.c_str());
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  for (const auto& load : std::vector<std::function<void()>>{[&] { (void)load_parallel_kf_params(fifo); },
                                                              [&] { (void)runtime::load_host_file(fifo); },
                                                              [&] { (void)imu::load_driver_config(fifo); },
                                                              [&] { (void)camera::load_tag_map(fifo); }}) {
    EXPECT_HAS(error_of(load), fifo + ": not a regular file (a FIFO, device or directory)");
  }
  EXPECT_HAS(error_of([] { (void)load_parallel_kf_params("/dev/zero"); }), "/dev/zero: not a regular file");
}

// Issue 33: `key:` or `key: ~` is a key given without a value. It was read as absent, so the
// default was kept silently (the file looked configured). Every loader refuses it naming the key,
// except the keys where null is documented to mean "learn it" (get_nullable: dip_deg, ...).
TEST(HostileConfig, GivenAKeyWithoutAValueInAnyLoaderWhenLoadedThenRefusedNamingTheKeyUnlessNullIsDocumented) {
  const std::string kf = write_file("null_kf.yaml", "parallel_kf:\n  mag_norm_tol:\n");
  const std::string gn = write_file("null_gn.yaml", "gauss_newton:\n  max_iterations: ~\n");
  const std::string ekf = write_file("null_ekf.yaml", "selective_ekf:\n  gauss_newton: {max_iterations: ~}\n");
  const std::string alt = write_file("null_alt.yaml", "cf:\n  sigma_baro_m:\n");
  const std::string veh = write_file("null_veh.yaml", "ekf:\n  r_mag_ut2: ~\n");
  struct Case {
    const char* loader;
    std::function<void()> load;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"parallel_kf", [&] { (void)load_parallel_kf_params(kf); }, kf + ": parallel_kf.mag_norm_tol has no value"},
      {"gauss_newton", [&] { (void)load_gauss_newton_params(gn); }, gn + ": gauss_newton.max_iterations has no value"},
      {"selective_ekf", [&] { (void)load_selective_ekf_params(ekf); },
       ekf + ": selective_ekf.gauss_newton.max_iterations has no value"},
      {"altitude", [&] { (void)load_altitude_params(alt); }, alt + ": cf.sigma_baro_m has no value"},
      {"vehicle", [&] { (void)load_vehicle_params(veh); }, veh + ": ekf.r_mag_ut2 has no value"},
      {"imu driver", [] { (void)imu::parse_driver_config("serial:\n  baud:\n", "drv.yaml"); },
       "drv.yaml: serial.baud has no value"},
      {"camera", [] { (void)camera::parse_camera_config("detector: {threads: ~}\n", "cam.yaml"); },
       "cam.yaml: detector.threads has no value"},
      {"component parameter", [] { (void)imu::imu_node_options(spec("imu_driver", "{port: ~}")); },
       "parameter 'port' of component 'imu_driver0' has no value"},
      {"ros2_bridge", [] { (void)ros2::parse_bridge_config(parse_yaml("world_frame: ~", "p"), "o"); },
       "o: ros2_bridge: 'world_frame' has no value"},
      {"north keys", [] { (void)read_north_params(parse_yaml("declination_deg:", "p")); },
       "declination_deg has no value"},
      {"north location", [] { (void)read_north_params(parse_yaml("location: ~", "p")); }, "location has no value"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.loader);
    EXPECT_HAS(error_of(c.load), c.message);
  }
  // documented nullable: `dip_deg: ~` is NaN ("learn it"), not an error
  const std::string gn_dip = write_file("null_gn_dip.yaml", "gauss_newton:\n  dip_deg: ~\n");
  EXPECT_TRUE(std::isnan(load_gauss_newton_params(gn_dip).dip_deg));
  // an empty section is an empty mapping: the defaults
  const std::string kf_empty = write_file("null_kf_section.yaml", "parallel_kf:\n  limits:\n");
  EXPECT_NO_THROW((void)load_parallel_kf_params(kf_empty));
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
