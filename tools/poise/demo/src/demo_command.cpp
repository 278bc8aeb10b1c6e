// `poise demo`: the main job on the embedded default. With no hardware it starts the simulated
// serial IMU on a pseudo-terminal (the serial driver reads it as it would a GY-87), a synthetic
// camera seeing AprilTags, and every estimator, in one host process; shows a live dashboard
// (each filter vs simulated truth, disturbance and magnetometer trust, tags in view, altitude,
// rates, latencies, rejections) through scripted episodes (magnet brought near, tag lost, stairs,
// magnet attached); stops after --duration or Ctrl-C and writes a report directory.
// With hardware: --port /dev/ttyUSB0 (and --camera /dev/video0 with --intrinsics/--tags).
#include "poise/cli/common.h"
#include "poise/demo/monitor.h"
#include "poise/demo/report.h"
#include "poise/runtime/host.h"
#include "poise/runtime/shipped.h"
#include "poise/sim/sensor_simulator.h"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>
#include <limits>
#include <thread>

namespace poise::cli {
namespace {

struct DemoOptions {
  int domain = 0;
  std::string profile;  // participant profile ("" = $POISE_DDS_PROFILE, else poise_default)
  double duration_s = 30.0;
  double rate_hz = 200.0;
  std::string scenario = "tour";
  uint64_t seed = 1;
  std::string port;        // real IMU instead of the simulator
  std::string imu_config;  // driver YAML for the real IMU
  std::string camera;      // real camera source instead of the synthetic one
  std::string intrinsics;
  std::string tags;
  std::string out = "poise-demo-report";
  bool no_camera = false;
  bool plain = false;      // no screen redraws (automatic when stdout is not a terminal)
  bool foxglove = false;   // --foxglove [PORT]: the foxglove_bridge component with the demo
  std::string foxglove_port;  // "" = 8765
};

// The synthetic camera's blackouts repeat every kCameraPeriodS (two 30 s tour cycles): the tag
// leaves the view for 4 s in the first cycle, and the camera sees nothing for 20 s in the second
// (the user looks away / walks off: the selective EKF runs on the IMU alone).
constexpr double kCameraPeriodS = 60.0;
constexpr double kTagLostStart = 9.0;
constexpr double kTagLostEnd = 13.0;
constexpr double kBlackoutStart = 35.0;
constexpr double kBlackoutEnd = 55.0;
// The synthetic camera's own corner noise per pixel axis, as the simulated IMU's figures are given
// to the filters (docs/CAMERA.md "Finding pixel_sigma_px": the harmonic mean of its frames' own
// fitted variances, 1 / mean((t - 2) / SSR), the prior's scale in the pooling; 0.080 px on three
// live demos. The RMS of its corner errors, 0.163 px, is heavy-tailed and held typical frames wide).
constexpr double kSimCameraPixelSigmaPx = 0.08;

/// The scripted episodes of the scenario over [0, duration].
std::vector<demo::Episode> episodes(const sim::SimConfig& config, double duration_s, bool camera) {
  std::vector<demo::Episode> out;
  const double cycle = config.cycle_s();
  for (double base = 0.0; base < duration_s; base += cycle) {
    for (const auto& m : config.magnets) {
      out.push_back({base + m.start_s, base + m.start_s + 2.0 * m.ramp_s + m.hold_s,
                     m.body_fixed ? "magnet attached" : "magnet near", 0});
    }
    double t = base;
    for (const auto& s : config.segments) {
      if (s.climb_rate_mps != 0.0) {
        out.push_back({t, t + s.duration_s, s.climb_rate_mps > 0 ? "stairs up" : "stairs down", 2});
      }
      t += s.duration_s;
    }
    if (cycle <= 0.0) {
      break;
    }
  }
  for (double base = 0.0; camera && base < duration_s; base += kCameraPeriodS) {
    out.push_back({base + kTagLostStart, base + kTagLostEnd, "tag lost", 1});
    if (base + kBlackoutStart < duration_s) {
      out.push_back({base + kBlackoutStart, base + kBlackoutEnd, "camera blackout 20 s", 1});
    }
  }
  return out;
}

std::string active_episodes(const std::vector<demo::Episode>& list, double t) {
  std::string s;
  for (const auto& e : list) {
    if (t >= e.start_s && t < e.end_s) {
      s += (s.empty() ? "" : ", ") + e.label;
    }
  }
  return s.empty() ? "-" : s;
}

YAML::Node map_of(std::initializer_list<std::pair<const char*, YAML::Node>> entries) {
  YAML::Node n(YAML::NodeType::Map);
  for (const auto& [k, v] : entries) {
    n[k] = v;
  }
  return n;
}

runtime::ComponentSpec component(const std::string& type, const std::string& name, YAML::Node params) {
  runtime::ComponentSpec c;
  c.type = type;
  c.name = name;
  c.params = params;
  c.origin = "poise demo (" + name + ")";
  return c;
}

std::string dashboard(const DemoOptions& o, const demo::PipelineMonitor& monitor,
                      const std::vector<std::string>& filters,
                      const std::vector<demo::Episode>& episode_list, const std::string& devices) {
  const double t = monitor.elapsed_s();
  const auto stats = monitor.filter_stats();
  std::ostringstream os;
  char line[256];
  std::snprintf(line, sizeof line, "poise demo   t = %5.1f / %.0f s   domain %d   %s\n", t, o.duration_s,
                o.domain, devices.c_str());
  os << line;
  const bool truth = o.port.empty();  // only the simulated IMU publishes a truth (and has a script)
  if (truth) {
    os << "episode: " << active_episodes(episode_list, t) << "\n";
  }
  os << "\n";
  std::snprintf(line, sizeof line, "%-14s %7s %8s %8s %8s %9s %17s\n", "filter", "rate", "roll",
                "pitch", "yaw", "error", "latency p50/p99");
  os << line;
  std::vector<std::string> rows;
  if (truth) {
    rows.emplace_back("truth");
  }
  rows.insert(rows.end(), filters.begin(), filters.end());
  for (const auto& f : rows) {
    const auto it = stats.find(f);
    if (it == stats.end()) {
      std::snprintf(line, sizeof line, "%-14s %7s\n", f.c_str(), "waiting");
      os << line;
      continue;
    }
    const auto& s = it->second;
    const Eigen::Vector3d rpy = s.latest.rpy_rad * 180.0 / M_PI;
    char err[32] = "";
    char lat[48] = "";
    if (f != "truth") {
      if (truth) {
        std::snprintf(err, sizeof err, "%.2f deg", s.error_deg);
      } else {
        std::snprintf(err, sizeof err, "-");
      }
      std::snprintf(lat, sizeof lat, "%.2f/%.2f ms", demo::percentile(s.latencies_ms, 50),
                    demo::percentile(s.latencies_ms, 99));
    }
    std::snprintf(line, sizeof line, "%-14s %5.0fHz %8.1f %8.1f %8.1f %9s %17s\n", f.c_str(), s.rate_hz,
                  rpy.x(), rpy.y(), rpy.z(), err, lat);
    os << line;
  }
  auto disturbance = [&](const char* f) {
    const auto it = stats.find(f);
    return it == stats.end() ? std::string("-") : [&] {
      char b[64];
      std::snprintf(b, sizeof b, "%.1f uT", it->second.latest.disturbance_norm_ut);
      return std::string(b);
    }();
  };
  auto trusted = [&](const char* f) {
    const auto it = stats.find(f);
    return it == stats.end() ? std::string("-") : std::string(it->second.latest.mag_trusted ? "yes" : "NO");
  };
  os << "\nmagnetic disturbance: " << (truth ? "truth " + disturbance("truth") + ", " : std::string())
     << "parallel_kf " << disturbance("parallel_kf") << "   magnetometer trusted: parallel_kf " << trusted("parallel_kf")
     << ", selective_ekf " << trusted("selective_ekf") << "\n";
  const auto cam = monitor.camera_stats();
  std::snprintf(line, sizeof line, "camera: %llu frames, tags in view %d, vision poses %llu%s\n",
                static_cast<unsigned long long>(cam.frames), cam.tags_in_view,
                static_cast<unsigned long long>(cam.poses),
                (cam.last_pose_t_s >= 0 && t - cam.last_pose_t_s > 0.5) ? "  (no pose: tag lost)" : "");
  os << line;
  const auto alt = monitor.altitude_series();
  const auto a = alt.find("altitude");
  const auto at = alt.find("truth");
  if (a != alt.end() && !a->second.empty()) {
    const auto& p = a->second.back();
    const double truth_h = (at != alt.end() && !at->second.empty()) ? at->second.back().height_m : std::numeric_limits<double>::quiet_NaN();
    const double truth_v =
        (at != alt.end() && !at->second.empty()) ? at->second.back().vertical_velocity_mps : std::numeric_limits<double>::quiet_NaN();
    if (truth) {
      std::snprintf(line, sizeof line,
                    "altitude: %.2f m (truth %.2f)   vertical velocity %.2f m/s (truth %.2f)   %s\n",
                    p.height_m, truth_h, p.vertical_velocity_mps, truth_v, p.stationary ? "stationary" : "moving");
    } else {
      std::snprintf(line, sizeof line, "altitude: %.2f m   vertical velocity %.2f m/s   %s\n", p.height_m,
                    p.vertical_velocity_mps, p.stationary ? "stationary" : "moving");
    }
    os << line;
  }
  os << "rejected:";
  const auto rejected = monitor.rejected_counts();
  if (rejected.empty()) {
    os << " -";
  }
  for (const auto& [name, n] : rejected) {
    os << " " << name << " " << n;
  }
  os << "\n";
  return os.str();
}

// not split: the demo's script in the order it runs (host file, scenario, host + monitor, dashboard
// loop, report); each step uses what the one before built.
void run_demo(const DemoOptions& o) {
  install_stop_handlers();
  auto& registry = runtime::ComponentRegistry::instance();
  const bool simulated_imu = o.port.empty();
  const std::string link = "/tmp/poise-demo-imu-" + std::to_string(::getpid());
  runtime::HostSpec spec;
  spec.participant_profile = o.profile;
  std::string devices;
  if (simulated_imu) {
    spec.components.push_back(component(
        "sim_imu", "sim_imu",
        map_of({{"link", YAML::Node(link)}, {"scenario", YAML::Node(o.scenario)},
                {"rate_hz", YAML::Node(o.rate_hz)}, {"seed", YAML::Node(o.seed)}})));
    devices = "simulated IMU on " + link;
  } else {
    devices = "IMU " + o.port;
  }
  YAML::Node driver = map_of({{"port", YAML::Node(simulated_imu ? link : o.port)}});
  if (!o.imu_config.empty()) {
    driver["config_file"] = o.imu_config;
  }
  spec.components.push_back(component("imu_driver", "imu0", driver));
  // The synthetic camera renders the simulated truth: with a real IMU (--port) it would see
  // nothing, so only a real camera (--camera) is used then.
  const bool camera = !o.no_camera && (!o.camera.empty() ? registry.find("camera") != nullptr
                                                          : simulated_imu && registry.find("sim_camera") != nullptr);
  if (camera) {
    if (o.camera.empty()) {
      spec.components.push_back(component(
          "sim_camera", "camera0",
          map_of({{"blackouts", YAML::Load("[[" + std::to_string(kTagLostStart) + ", " +
                                           std::to_string(kTagLostEnd) + "], [" +
                                           std::to_string(kBlackoutStart) + ", " +
                                           std::to_string(kBlackoutEnd) + "]]")},
                  {"blackout_period_s", YAML::Node(kCameraPeriodS)},
                  {"pixel_sigma_px", YAML::Node(kSimCameraPixelSigmaPx)}})));
      devices += ", synthetic camera";
    } else {
      if (o.intrinsics.empty() || o.tags.empty()) {
        throw Error("--camera needs --intrinsics FILE and --tags FILE", kUsageExitCode);
      }
      spec.components.push_back(component(
          "camera", "camera0",
          map_of({{"source", YAML::Node(o.camera)}, {"intrinsics_file", YAML::Node(o.intrinsics)},
                  {"tags_file", YAML::Node(o.tags)}})));
      devices += ", camera " + o.camera;
    }
  }
  std::vector<std::string> filters;
  for (const char* f : {"parallel_kf", "selective_ekf", "gauss_newton"}) {
    // the selective EKF: with a camera, or on a real IMU alone as before the synthetic camera was
    // left out there (--no-camera: without it)
    const bool selective_runs = camera || (!simulated_imu && !o.no_camera);
    if (registry.find(f) != nullptr && (std::string(f) != "selective_ekf" || selective_runs)) {
      YAML::Node params(YAML::NodeType::Map);
      if (std::string(f) == "selective_ekf" && o.camera.empty()) {
        params["q_body_camera"] = YAML::Load("[0, 1, 0, 0]");  // the synthetic camera looks down
      }
      if (simulated_imu && (std::string(f) == "parallel_kf" || std::string(f) == "selective_ekf")) {
        // the simulated sensor's own figures, for the published covariance: its gyro's bias walk
        // (its scenario's; 0: a constant bias), bias at start and white noise density (its per-sample sigma over
        // sqrt(rate); docs/ESTIMATORS.md "The gyro's bias walk"), and for the selective EKF the
        // accelerometer's density too (docs/SELECTIVE_EKF.md "The sensor's own figures")
        const sim::SensorNoise noise = sim::make_scenario(o.scenario, o.rate_hz, o.seed).noise;
        params["gyro_bias_walk_rps_per_sqrt_s"] = noise.gyro_bias_walk_rps_per_sqrt_s;
        params["gyro_noise_density_rps_per_sqrt_hz"] = noise.sigma_gyro_rps / std::sqrt(o.rate_hz);
        const double bias_rms = std::sqrt(noise.gyro_bias_rps.squaredNorm() / 3.0);
        if (std::string(f) == "parallel_kf" && bias_rms > 0.0) {
          // its bias at start: the RMS per axis of the constant one it draws (docs/ESTIMATORS.md
          // "The gyro's bias at start")
          params["gyro_initial_bias_sd_rps"] = bias_rms;
        }
        if (std::string(f) == "parallel_kf") {
          params["gyro_scale_error"] = 0.0;  // the simulated gyro has none (as simulated.yaml says)
        }
        if (std::string(f) == "selective_ekf") {
          params["accel_noise_density_mps2_per_sqrt_hz"] = noise.sigma_accel_mps2 / std::sqrt(o.rate_hz);
        }
      }
      spec.components.push_back(component(f, f, params));
      filters.emplace_back(f);
    }
  }
  if (registry.find("altitude") != nullptr) {
    spec.components.push_back(
        component("altitude", "altitude", map_of({{"relative_to_start", YAML::Node(true)}})));
  }
  std::string foxglove_url;
  if (o.foxglove) {
    if (registry.find("foxglove_bridge") == nullptr) {
      throw Error("--foxglove: this poise was built without the foxglove_bridge component");
    }
    int port = 8765;
    try {
      std::size_t used = 0;
      port = o.foxglove_port.empty() ? 8765 : std::stoi(o.foxglove_port, &used);
      if (!o.foxglove_port.empty() && used != o.foxglove_port.size()) {
        throw std::invalid_argument("trailing characters");
      }
    } catch (const std::exception&) {
      port = -1;
    }
    if (port < 1 || port > 65535) {
      throw Error("--foxglove: '" + o.foxglove_port + "' is not a TCP port (1-65535)", kUsageExitCode);
    }
    spec.components.push_back(component("foxglove_bridge", "foxglove", map_of({{"port", YAML::Node(port)}})));
    char host_name[256] = "localhost";
    if (::gethostname(host_name, sizeof host_name - 1) != 0) {
      std::snprintf(host_name, sizeof host_name, "localhost");
    }
    foxglove_url = "ws://" + std::string(host_name) + ":" + std::to_string(port);
    devices += ", Foxglove " + foxglove_url;
  }

  sim::SimConfig scenario;
  try {
    scenario = sim::make_scenario(o.scenario, o.rate_hz, o.seed);
  } catch (const std::invalid_argument& e) {
    throw Error(std::string("--scenario: ") + e.what(), kUsageExitCode);
  }
  const auto episode_list = simulated_imu ? episodes(scenario, o.duration_s, camera && o.camera.empty())
                                          : std::vector<demo::Episode>{};

  runtime::Host host(spec, o.domain);
  demo::PipelineMonitor monitor(host.participant(), spec.topics, filters);
  host.start();
  if (!foxglove_url.empty()) {
    std::printf("Foxglove: open %s (or ws://localhost:%s on this host) in Foxglove or Lichtblick; layout "
                "%s\n",
                foxglove_url.c_str(), foxglove_url.substr(foxglove_url.rfind(':') + 1).c_str(),
                runtime::shipped_file_hint("foxglove/poise.json").c_str());
    std::fflush(stdout);
  }
  const bool redraw = !o.plain && ::isatty(STDOUT_FILENO) != 0;
  auto next_draw = std::chrono::steady_clock::now();
  while (!stop_requested() && monitor.elapsed_s() < o.duration_s) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const auto now = std::chrono::steady_clock::now();
    if (now < next_draw) {
      continue;
    }
    const std::string text = dashboard(o, monitor, filters, episode_list, devices);
    if (redraw) {
      std::printf("\033[H\033[2J%s", text.c_str());
      next_draw = now + std::chrono::milliseconds(250);
    } else {
      std::printf("%s\n", text.c_str());
      next_draw = now + std::chrono::seconds(5);
    }
    std::fflush(stdout);
  }
  host.stop();

  demo::ReportInput input;
  input.title = "poise demo";
  input.filters = filters;
  input.episodes = episode_list;
  input.simulated_truth = simulated_imu;
  input.notes = {"devices: " + devices,
                 simulated_imu ? "scenario: " + o.scenario + " (seed " + std::to_string(o.seed) + "), IMU " +
                                     std::to_string(static_cast<int>(o.rate_hz)) + " Hz"
                               : "real hardware: no simulated scenario, no truth",
                 "duration: " + std::to_string(static_cast<int>(monitor.elapsed_s())) + " s"};
  const std::string index = demo::write_report(o.out, input, monitor);
  std::printf("%s\nreport: %s\n", dashboard(o, monitor, filters, episode_list, devices).c_str(),
              std::filesystem::absolute(index).c_str());
  const auto stats = monitor.filter_stats();
  if (simulated_imu) {  // a real IMU has no truth to compare with
    std::printf("against the simulated truth (NEES of the published attitude_covariance; consistent: median "
                "about 2.37, 95 %% inside):\n");
  }
  for (const auto& f : filters) {
    const auto it = stats.find(f);
    if (it == stats.end() || it->second.compared == 0) {
      continue;
    }
    const demo::FilterStats& s = it->second;
    std::printf("  %-14s RMSE %.3f deg, median NEES %.3g, %.1f %% inside the 95 %% ellipsoid (%llu samples, %llu "
                "without a usable covariance)\n",
                f.c_str(), std::sqrt(s.sum_sq_error / static_cast<double>(s.compared)), s.nees.median(),
                100.0 * s.nees.fraction_inside(kNees95Dof3), static_cast<unsigned long long>(s.nees.samples()),
                static_cast<unsigned long long>(s.nees.without_covariance()));
  }
  for (const auto& f : filters) {
    if (stats.count(f) == 0 || stats.at(f).received == 0) {
      throw Error("no estimate from " + f + " was received: the pipeline did not run (see above)");
    }
  }
}

}  // namespace

void register_demo_commands(CLI::App& app) {
  auto o = std::make_shared<DemoOptions>();
  CLI::App* demo = app.add_subcommand(
      "demo", "The main job: IMU (simulated on a pseudo-terminal, or --port) + camera (synthetic, or "
              "--camera) + every estimator, live dashboard, report");
  add_domain_option(demo, &o->domain);
  add_dds_profile_option(demo, &o->profile);
  demo->add_option("--duration", o->duration_s, "Run time, s")->check(CLI::PositiveNumber)->capture_default_str();
  demo->add_option("--rate", o->rate_hz, "Simulated IMU rate, Hz")->check(CLI::Range(10.0, 2000.0))->capture_default_str();
  demo->add_option("--scenario", o->scenario, "Simulator scenario (tour, demo, static_magnet, fast_motion, random_motion)")
      ->capture_default_str();
  demo->add_option("--seed", o->seed, "Simulator seed")->capture_default_str();
  demo->add_option("--port", o->port, "Real IMU serial port (e.g. /dev/ttyUSB0) instead of the simulator");
  demo->add_option("--imu-config", o->imu_config, "Driver YAML for --port (calibration, axes)")->check(CLI::ExistingFile);
  demo->add_option("--camera", o->camera, "Real camera source (e.g. /dev/video0) instead of the synthetic one");
  demo->add_option("--intrinsics", o->intrinsics, "Camera intrinsics YAML (with --camera)")->check(CLI::ExistingFile);
  demo->add_option("--tags", o->tags, "Tag map YAML (with --camera)")->check(CLI::ExistingFile);
  demo->add_flag("--no-camera", o->no_camera, "Run without a camera (no selective EKF)");
  add_out_dir_option(demo, &o->out, "the report", false)->capture_default_str();
  add_deprecated_alias(demo, "--out", "--out-dir", &o->out);
  demo->add_flag("--plain", o->plain, "Print status blocks instead of redrawing the screen");
  CLI::Option* foxglove = demo->add_option("--foxglove", o->foxglove_port,
                                           "Serve the demo to Foxglove / Lichtblick over WebSocket on PORT "
                                           "(default 8765) and print the URL (docs/FOXGLOVE.md)")
                              ->expected(0, 1);
  demo->callback([o, foxglove] {
    o->foxglove = foxglove->count() > 0;
    run_demo(*o);
  });
}

}  // namespace poise::cli
