// The shipped host files (config/hosts/*.yaml) parse, and every estimator (and ROS 2 bridge) in them is
// created with its parameters validated (drivers need their devices and are left out here).
#include "poise/ros2_bridge/bridge.h"
#include "poise/runtime/host.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <set>
#include <string>
#include <vector>

namespace poise::runtime {
void register_estimator_nodes(ComponentRegistry& registry);
}

namespace poise::testing {
namespace {

void register_nodes() {
  auto& registry = runtime::ComponentRegistry::instance();
  if (registry.find("selective_ekf") == nullptr) {
    runtime::register_estimator_nodes(registry);
  }
  if (registry.find("ros2_bridge") == nullptr) {
    ros2::register_ros2_bridge(registry);
  }
}

TEST(HostFiles, GivenEachShippedHostFileWhenLoadedThenItsEstimatorsAreCreated) {
  register_nodes();
  const std::set<std::string> estimators{"parallel_kf", "selective_ekf", "gauss_newton", "altitude", "vehicle",
                                         "ros2_bridge"};
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(source_path("config/hosts"))) {
    if (entry.path().extension() != ".yaml") {
      continue;
    }
    SCOPED_TRACE(entry.path().string());
    runtime::HostSpec spec = runtime::load_host_file(entry.path().string());
    std::vector<runtime::ComponentSpec> kept;
    for (const auto& c : spec.components) {
      if (estimators.count(c.type) != 0) {
        kept.push_back(c);
      }
    }
    // Move, not copy-assign: ComponentSpec holds YAML::Node, whose operator= writes through to the
    // node it refers to (yaml-cpp reference semantics) and would overwrite other specs' params.
    spec.components = std::move(kept);
    DomainLease domain;
    EXPECT_NO_THROW(runtime::Host(spec, domain.id()));
    ++files;
  }
  EXPECT_GE(files, 4);
}

TEST(HostFiles, GivenAnImuDelayOutOfRangeWhenCreatedThenConfigErrorNamesIt) {
  register_nodes();
  DomainLease domain;
  const runtime::HostSpec spec = runtime::parse_host(
      YAML::Load("components: [{type: selective_ekf, name: s, params: {imu_delay_s: 0.5}}]"), "test", ".");
  try {
    runtime::Host host(spec, domain.id());
    ADD_FAILURE() << "no error for imu_delay_s 0.5";
  } catch (const runtime::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("imu_delay_s"), std::string::npos) << e.what();
  }
}

/// Component `type` with each of `keys` as a parameter: every value of `good` is taken; a
/// negative, huge, infinite or textual one is a ConfigError naming the key.
void expect_sensor_figure_params(const std::string& type, const std::vector<std::string>& keys,
                                 const std::vector<std::string>& good) {
  register_nodes();
  DomainLease domain;
  for (const std::string& key : keys) {
    auto host_with = [&](const std::string& value) {
      return runtime::parse_host(
          YAML::Load("components: [{type: " + type + ", name: c, params: {" + key + ": " + value + "}}]"), "test", ".");
    };
    for (const std::string& value : good) {
      EXPECT_NO_THROW(runtime::Host(host_with(value), domain.id())) << key << " " << value;
    }
    for (const char* bad : {"-1e-6", "1e308", ".inf", "fast"}) {
      try {
        runtime::Host host(host_with(bad), domain.id());
        ADD_FAILURE() << "no error for " << key << " " << bad;
      } catch (const runtime::ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << bad << ": " << e.what();
      }
    }
  }
}

// The parallel KF component's gyro_bias_walk_rps_per_sqrt_s (the gyro's own bias random walk),
// gyro_noise_density_rps_per_sqrt_hz (its white noise density) and gyro_scale_error (its
// scale-factor error), all for the published covariance: a figure in range is taken, anything
// else is a ConfigError naming the key.
TEST(HostFiles, GivenAGyroFigureParamWhenTheParallelKfIsCreatedThenARangeFigureIsTakenAndAHostileOneNamed) {
  expect_sensor_figure_params("parallel_kf",
                              {"gyro_bias_walk_rps_per_sqrt_s", "gyro_noise_density_rps_per_sqrt_hz", "gyro_scale_error"},
                              {"0.0", "2.0e-5"});
}

// The selective EKF component's figures of the sensor (gyro and accelerometer noise densities,
// gyro bias walk; for the published covariance): a figure in range is taken, anything else is a
// ConfigError naming its key.
TEST(HostFiles, GivenTheSensorFiguresAsParamsWhenTheSelectiveEkfIsCreatedThenRangeFiguresAreTakenAndHostileOnesNamed) {
  expect_sensor_figure_params("selective_ekf",
                              {"gyro_noise_density_rps_per_sqrt_hz", "accel_noise_density_mps2_per_sqrt_hz",
                               "gyro_bias_walk_rps_per_sqrt_s"},
                              {"1.0e-4"});
}

// Every attitude node takes the same north keys; a location (WMM2025) or a declination in
// degrees is accepted, and a bad one is a ConfigError saying what to fix.
TEST(HostFiles, GivenNorthSettingsWhenEachAttitudeNodeIsCreatedThenTheyAreAcceptedOrNamed) {
  register_nodes();
  const std::string good[] = {
      "{declination_deg: 3.5}",
      "{location: {lat_deg: 48.14, lon_deg: 11.58, alt_m: 520}, date: 2026-11-24}",
      "{location: {lat_deg: -33.9, lon_deg: 151.2}, date: 2027.5, seed_field: false}",
  };
  const std::pair<std::string, std::string> bad[] = {
      {"{declination_deg: 3.5, location: {lat_deg: 1, lon_deg: 2}}", "not both"},
      {"{location: {lat_deg: 48}}", "lon_deg"},
      {"{location: {lat_deg: 48, lon_deg: 11, height: 3}}", "location.height"},
      {"{location: {lat_deg: 48, lon_deg: 11}, date: 2019-01-01}", "validity"},
      {"{date: 2026-01-01}", "need a location"},
      {"{declination_deg: 400}", "declination_deg"},
  };
  for (const char* type : {"parallel_kf", "selective_ekf", "gauss_newton", "vehicle"}) {
    for (const std::string& params : good) {
      SCOPED_TRACE(std::string(type) + " " + params);
      DomainLease domain;
      const runtime::HostSpec spec = runtime::parse_host(
          YAML::Load("components: [{type: " + std::string(type) + ", name: n, params: " + params + "}]"), "test", ".");
      EXPECT_NO_THROW(runtime::Host(spec, domain.id()));
    }
    for (const auto& [params, named] : bad) {
      SCOPED_TRACE(std::string(type) + " " + params);
      DomainLease domain;
      const runtime::HostSpec spec = runtime::parse_host(
          YAML::Load("components: [{type: " + std::string(type) + ", name: n, params: " + params + "}]"), "test", ".");
      try {
        runtime::Host host(spec, domain.id());
        ADD_FAILURE() << "accepted";
      } catch (const runtime::ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
      }
    }
  }
}

}  // namespace
}  // namespace poise::testing
