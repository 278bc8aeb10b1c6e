// Host files are validated with clear errors; a Host constructs, starts and stops its components.
#include "poise/runtime/host.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace poise::runtime {
namespace {

HostSpec parse(const std::string& yaml) { return parse_host(YAML::Load(yaml), "test.yaml", "/cfg", ""); }

/// A temporary directory with files, removed at the end of the test.
class TempTree {
 public:
  TempTree() : root_(std::filesystem::temp_directory_path() / ("poise_host_tree_" + std::to_string(::getpid()))) {
    std::filesystem::remove_all(root_);
    std::filesystem::create_directories(root_);
  }
  ~TempTree() { std::filesystem::remove_all(root_); }
  TempTree(const TempTree&) = delete;
  TempTree& operator=(const TempTree&) = delete;
  /// Writes `text` to `relative` (directories created); returns its path.
  std::string write(const std::string& relative, const std::string& text) const {
    const auto p = root_ / relative;
    std::filesystem::create_directories(p.parent_path());
    std::ofstream(p) << text;
    return p.string();
  }
  [[nodiscard]] std::string path(const std::string& relative) const { return (root_ / relative).string(); }

 private:
  std::filesystem::path root_;
};

std::string error_of(const std::string& yaml) {
  try {
    parse(yaml);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

std::string realtime_error(const std::string& map) {
  return error_of("realtime: " + map + "\ncomponents: [{type: parallel_kf}]\n");
}

TEST(HostFile, GivenARealtimeSectionWhenParsedThenEachKeyIsReadAndBadValuesNameTheKey) {
  const HostSpec spec = parse("realtime: {priority: 80, cpus: [2, 3], lock_memory: true}\n"
                              "components: [{type: parallel_kf}]\n");
  EXPECT_EQ(spec.realtime.priority, 80);
  EXPECT_EQ(spec.realtime.cpus, (std::vector<int>{2, 3}));
  EXPECT_TRUE(spec.realtime.lock_memory);
  EXPECT_FALSE(parse("components: [{type: parallel_kf}]\n").realtime.any());
  EXPECT_NE(realtime_error("{priority: 100}").find("test.yaml: realtime.priority must be 1-99"), std::string::npos);
  EXPECT_NE(realtime_error("{priority: -1}").find("realtime.priority"), std::string::npos);
  EXPECT_NE(realtime_error("{cpus: []}").find("realtime.cpus"), std::string::npos);
  EXPECT_NE(realtime_error("{cpus: [-1]}").find("cpu -1 is out of range"), std::string::npos);
  EXPECT_NE(realtime_error("{cpus: [1, 1]}").find("twice"), std::string::npos);
  EXPECT_NE(realtime_error("{prio: 5}").find("test.yaml: unknown key 'realtime.prio' (known: priority, cpus, lock_memory)"), std::string::npos);
  EXPECT_NE(realtime_error("[1]").find("must be a map"), std::string::npos);
  EXPECT_NE(realtime_error("{priority: high}").find("test.yaml: realtime"), std::string::npos);
}

TEST(HostFile, ParsesComponentsTopicsAndDomain) {
  const HostSpec spec = parse(R"(
domain: 12
participant_profile: poise_udp
topics: {imu: imu_left, attitude_prefix: "est/"}
components:
  - type: parallel_kf
  - type: gauss_newton
    name: gn
    params: {max_iterations: 5}
)");
  EXPECT_EQ(spec.domain, 12);
  EXPECT_EQ(spec.participant_profile, "poise_udp");
  EXPECT_EQ(spec.topics.imu, "imu_left");
  EXPECT_EQ(spec.topics.attitude("gn"), "est/gn");
  EXPECT_EQ(spec.topics.altitude, "altitude") << "defaults stay for names not overridden";
  ASSERT_EQ(spec.components.size(), 2U);
  EXPECT_EQ(spec.components[0].name, "parallel_kf") << "the name defaults to the type";
  EXPECT_EQ(spec.components[1].name, "gn");
  EXPECT_EQ(spec.components[1].params["max_iterations"].as<int>(), 5);
}

// `poise run --set NAME.key=VALUE` and `poise process --set` (e.g. the north keys of one
// component): the value is YAML, put into that component's params; errors name the assignment.
TEST(HostFile, GivenSetsWhenAppliedThenTheNamedComponentsParamsChangeAndBadOnesAreRefused) {
  HostSpec spec = parse("components:\n  - {type: parallel_kf, name: pkf}\n  - {type: gauss_newton, name: gn}\n");
  apply_component_sets({"pkf.declination_deg=3.4", "pkf.location={lat_deg: 48.1, lon_deg: 11.6}",
                        "gn.max_iterations=7"},
                       spec);
  EXPECT_EQ(spec.components[0].params["declination_deg"].as<double>(), 3.4);
  EXPECT_EQ(spec.components[0].params["location"]["lon_deg"].as<double>(), 11.6);
  EXPECT_EQ(spec.components[1].params["max_iterations"].as<int>(), 7);
  EXPECT_NE(spec.components[0].origin.find("with --set pkf.declination_deg=3.4"), std::string::npos);
  auto error = [&](const std::string& set) {
    try {
      apply_component_sets({set}, spec);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error("nobody.x=1").find("no component named 'nobody' in the host file (pkf, gn)"), std::string::npos);
  EXPECT_NE(error("declination_deg=3.4").find("expected NAME.key=value"), std::string::npos);
  EXPECT_NE(error("pkf.x=[1,").find("not YAML"), std::string::npos);
}

TEST(HostFile, FileParametersResolveAgainstTheHostFile) {
  TempTree t;
  t.write("cfg/f/x.yaml", "a: 1\n");
  const HostSpec spec = parse_host(YAML::Load("components: [{type: a, params: {filter_file: f/x.yaml, other: f/y}}]"),
                                   "test.yaml", t.path("cfg"), "");
  EXPECT_EQ(spec.components[0].params["filter_file"].as<std::string>(), t.path("cfg/f/x.yaml"));
  EXPECT_EQ(spec.components[0].params["other"].as<std::string>(), "f/y") << "only *_file keys are paths";
  const HostSpec absolute = parse("components: [{type: a, params: {filter_file: /nowhere/x.yaml}}]");
  EXPECT_EQ(absolute.components[0].params["filter_file"].as<std::string>(), "/nowhere/x.yaml")
      << "an absolute path is taken as it is (its loader reports it missing)";
}

// A shipped host file copied to /etc/poise names `../filters/...` and `../drivers/...`: relative
// to the copy they do not exist, relative to the shipped host files they do.
TEST(HostFile, GivenAShippedHostFileCopiedElsewhereWhenItsFilesAreNotBesideItThenTheShippedOnesAreUsed) {
  TempTree t;
  const std::string shipped_alt = t.write("share/poise/filters/altitude.yaml", "a: 1\n");
  const std::string shipped_imu = t.write("share/poise/drivers/imu.yaml", "serial: {}\n");
  const std::string shipped_qos = t.write("share/poise/qos/poise_profiles.xml", "<dds/>\n");
  const std::string shipped_cfg = t.write("share/poise/filters/p.yaml", "b: 2\n");
  const std::string own_imu = t.write("etc/drivers/imu.yaml", "serial: {}\n");  // beside the copy
  const std::string host = R"(
qos_file: ../qos/poise_profiles.xml
components:
  - {type: imu_driver, params: {config_file: ../drivers/imu.yaml}}
  - {type: altitude, config: ../filters/p.yaml, params: {filter_file: ../filters/altitude.yaml}}
)";
  const HostSpec spec = parse_host(YAML::Load(host), "/etc/poise/robot.yaml", t.path("etc/poise"),
                                   t.path("share/poise/hosts"));
  EXPECT_EQ(spec.qos_file, shipped_qos);
  EXPECT_EQ(spec.components[0].params["config_file"].as<std::string>(), own_imu)
      << "a file beside the host file comes first";
  EXPECT_EQ(spec.components[1].params["filter_file"].as<std::string>(), shipped_alt);
  EXPECT_EQ(spec.components[1].params["b"].as<int>(), 2) << "the config file came from " << shipped_cfg;
  std::filesystem::remove(own_imu);
  const HostSpec shipped = parse_host(YAML::Load(host), "/etc/poise/robot.yaml", t.path("etc/poise"),
                                      t.path("share/poise/hosts"));
  EXPECT_EQ(shipped.components[0].params["config_file"].as<std::string>(), shipped_imu);
}

TEST(HostFile, GivenARelativePathFoundNowhereWhenParsedThenTheErrorNamesEveryPathTried) {
  TempTree t;
  t.write("share/poise/hosts/robot.yaml", "components: []\n");
  const auto error = [&](const std::string& yaml, const std::string& shipped) {
    try {
      (void)parse_host(YAML::Load(yaml), "/etc/poise/robot.yaml", "/etc/poise", shipped);
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const std::string e = error("components: [{type: imu_driver, name: imu0, params: {config_file: ../drivers/none.yaml}}]",
                              t.path("share/poise/hosts"));
  EXPECT_NE(e.find("/etc/poise/robot.yaml: components[0] (imu0): params.config_file '../drivers/none.yaml' not found"),
            std::string::npos) << e;
  EXPECT_NE(e.find("not found at /etc/drivers/none.yaml (beside the host file) nor at " +
                   t.path("share/poise/drivers/none.yaml") + " (beside the shipped host files)"),
            std::string::npos) << e;
  EXPECT_EQ(e.find("config/drivers"), std::string::npos) << "no source-tree path: " << e;
  const std::string q = error("qos_file: q.xml\ncomponents: [{type: a}]", "");
  EXPECT_NE(q.find("qos_file 'q.xml' not found at /etc/poise/q.xml (beside the host file; no shipped "
                   "configuration was found beside this executable)"),
            std::string::npos) << q;
}

TEST(HostFile, ErrorsNameTheProblem) {
  EXPECT_NE(error_of("components: []").find("non-empty"), std::string::npos);
  EXPECT_NE(error_of("domian: 3\ncomponents: [{type: a}]").find("unknown key 'domian'"),
            std::string::npos);
  EXPECT_NE(error_of("domain: 300\ncomponents: [{type: a}]").find("0-232"), std::string::npos);
  EXPECT_NE(error_of("components: [{type: a}, {type: a}]").find("named 'a'"), std::string::npos);
  EXPECT_NE(error_of("components: [{name: x}]").find("'type'"), std::string::npos);
  EXPECT_NE(error_of("topics: {imus: x}\ncomponents: [{type: a}]").find("unknown key 'topics.imus' (known: imu, "),
            std::string::npos);
  EXPECT_NE(error_of("components: [{type: a, config: missing.yaml}]").find("/cfg/missing.yaml"),
            std::string::npos)
      << "relative config paths resolve against the host file's directory";
}

TEST(HostFile, InlineParamsOverrideTheConfigFile) {
  const auto dir = std::filesystem::temp_directory_path() / ("poise_host_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "p.yaml") << "a: 1\nb: 2\n";
  std::ofstream(dir / "host.yaml") << "components:\n  - type: t\n    config: p.yaml\n    params: {b: 3}\n";
  const HostSpec spec = load_host_file((dir / "host.yaml").string());
  EXPECT_EQ(spec.components[0].params["a"].as<int>(), 1);
  EXPECT_EQ(spec.components[0].params["b"].as<int>(), 3);
  std::filesystem::remove_all(dir);
}

TEST(HostFile, MissingFileIsAClearError) {
  EXPECT_THROW(load_host_file("/nonexistent/host.yaml"), ConfigError);
}

TEST(ComponentParams, UnknownAndMistypedParametersAreRejected) {
  ComponentSpec spec;
  spec.type = "t";
  spec.name = "n";
  spec.origin = "test";
  spec.params = YAML::Load("{rate: fast, good: 1}");
  EXPECT_THROW(param<double>(spec, "rate", 1.0), ConfigError);
  EXPECT_EQ(param<int>(spec, "good", 0), 1);
  EXPECT_EQ(param<int>(spec, "absent", 7), 7);
  EXPECT_THROW(check_known_params(spec, {"rate"}), ConfigError);
  EXPECT_NO_THROW(check_known_params(spec, {"rate", "good"}));
}

/// A component that records its lifecycle.
struct Lifecycle {
  int created = 0;
  int started = 0;
  int stopped = 0;
  int destroyed = 0;
};

class Probe : public Component {
 public:
  explicit Probe(Lifecycle& l) : l_(l) { ++l_.created; }
  ~Probe() override { ++l_.destroyed; }
  void start() override { ++l_.started; }
  void stop() override { ++l_.stopped; }
  [[nodiscard]] std::string status() const override { return "ok"; }

 private:
  Lifecycle& l_;
};

TEST(Host, RunsComponentsThroughTheirLifecycle) {
  static Lifecycle lifecycle;
  if (ComponentRegistry::instance().find("test_probe") == nullptr) {
    ComponentRegistry::instance().add({"test_probe", "lifecycle probe",
                                       [](const ComponentSpec&, HostContext&) {
                                         return std::make_unique<Probe>(lifecycle);
                                       }});
  }
  testing::DomainLease domain;
  const HostSpec spec = parse("components: [{type: test_probe, name: a}, {type: test_probe, name: b}]");
  {
    Host host(spec, domain.id());
    EXPECT_EQ(lifecycle.created, 2);
    host.start();
    EXPECT_EQ(lifecycle.started, 2);
    EXPECT_EQ(host.status(), (std::vector<std::string>{"a: ok", "b: ok"}));
    host.stop();
    EXPECT_EQ(lifecycle.stopped, 2);
  }
  EXPECT_EQ(lifecycle.destroyed, 2);
}

TEST(Host, UnknownComponentTypeListsTheKnownOnes) {
  testing::DomainLease domain;
  try {
    Host host(parse("components: [{type: no_such_thing}]"), domain.id());
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown component type 'no_such_thing'"), std::string::npos);
  }
}

}  // namespace
}  // namespace poise::runtime
