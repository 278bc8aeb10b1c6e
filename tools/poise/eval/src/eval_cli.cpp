// `poise eval broad` and `poise bench filters`.
#include "poise/cli/common.h"
#include "poise/runtime/utc_date.h"
#include "poise/cli/progress.h"
#include "poise/bench/bench.h"
#include "poise/eval/broad.h"
#include "poise/eval/crossval.h"
#include "poise/eval/filter_registry.h"
#include "poise/eval/imu_delay.h"
#include "poise/eval/north_filter.h"
#include "poise/eval/runner.h"
#include "poise/sim/sensor_simulator.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <fstream>
#include <memory>
#include <sstream>
#include <utility>
#include <string>
#include <vector>

namespace poise::cli {
namespace {

std::string filter_list() {
  std::string s;
  for (const auto& e : eval::registered_filters()) {
    s += "\n  " + e.name + ": " + e.description;
  }
  return s;
}

std::unique_ptr<AttitudeFilter> make_or_throw(const std::string& name, const std::string& config,
                                              const NorthReference& north) {
  try {
    return eval::with_north(eval::make_filter_for_broad(name, config), north);
  } catch (const std::exception& e) {
    throw Error(std::string(e.what()) + "; filters:" + filter_list());
  }
}

/// `--set KEY=VALUE` (the north keys, as in a host file's component params): the north every
/// filter of the command outputs in; said on stderr when it is true north.
NorthReference north_option(const std::vector<std::string>& sets, const std::string& command) {
  NorthReference north;
  try {
    north = eval::north_from_sets(sets, runtime::utc_today());
  } catch (const std::invalid_argument& e) {
    throw Error(e.what(), kUsageExitCode);
  }
  if (north.true_north) {
    std::cerr << command << ": outputs in true ENU (" << north.frame_id() << "), declination "
              << north.declination_rad / kRadPerDeg << " deg east (" << north.source << ")\n";
  }
  return north;
}

/// Adds `--set KEY=VALUE` for the north keys.
void add_north_set_option(CLI::App* sub, std::vector<std::string>* sets) {
  sub->add_option("--set", *sets,
                  "KEY=VALUE: true north, as in a host file's component params (repeatable): "
                  "declination_deg=D (deg east), or location={lat_deg: .., lon_deg: .., alt_m: ..} "
                  "with optional date=YYYY-MM-DD (WMM2025); outputs then in true ENU")
      ->allow_extra_args(false)
      ->type_name("KEY=VALUE");
}

/// What `poise eval broad` and `poise tune` do to each trial before a filter sees it.
struct TrialTransform {
  size_t every = 1;          ///< every N-th row of each trial (1 = all): a lower-rate sensor
  double magnet_ut = 0.0;    ///< an attached magnet emulated: offset magnitude, uT (0 = none)
  double magnet_at = 1.0 / 3.0;  ///< ... from this fraction of the trial's duration on
};

/// Loads each file; EVERY > 1: every EVERY-th row as recorded (eval::decimate_trial); MAGNET_UT > 0:
/// a body-fixed offset from MAGNET_AT of the trial on (eval::attach_magnet), its direction drawn
/// from the trial's number.
std::vector<eval::BroadTrial> load_trials(const std::vector<std::string>& files, const TrialTransform& t = {}) {
  std::vector<eval::BroadTrial> trials;
  for (size_t i = 0; i < files.size(); ++i) {
    if (stop_requested()) {
      throw Error("interrupted");
    }
    try {
      eval::BroadTrial trial = eval::load_broad(files[i]);
      if (t.every != 1) {
        trial = eval::decimate_trial(trial, t.every);
      }
      if (t.magnet_ut > 0.0) {
        const double from_s = t.magnet_at * static_cast<double>(trial.size()) / trial.rate_hz;
        trial = eval::attach_magnet(trial, eval::attached_magnet_offset(trial.number, t.magnet_ut), from_s);
      }
      trials.push_back(std::move(trial));
    } catch (const std::exception& e) {
      throw Error(std::string(e.what()) + " (pass BROAD-layout .hdf5 files, e.g. ../shared/broad/*.hdf5)");
    }
  }
  return trials;
}

/// ESTIMATED: samples after which the filter was initialised. With none (the filter rejected every
/// sample) the identities in Q are no estimate: the trial gets no figure, so every mean and the
/// choice of `tune` leave it out (never the initial quaternion's error averaged in).
eval::TrialResult score(const eval::BroadTrial& trial, const std::vector<Eigen::Quaterniond>& q, size_t estimated) {
  eval::TrialResult r;
  r.stem = trial.stem;
  r.number = trial.number;
  r.disturbed = trial.disturbed();
  if (estimated > 0) {
    r.errors = eval::broad_errors(q, trial);
  }
  return r;
}

std::string no_estimate_note(const std::string& stem) {
  return stem + ": the filter rejected every sample (no estimate): excluded from the means";
}

void make_dir(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    throw Error("cannot create output directory '" + dir + "': " + ec.message());
  }
}

void run_eval(const std::string& filter_name, const std::string& config, const std::string& out_dir,
              const std::vector<std::string>& files, const NorthReference& north, const TrialTransform& transform) {
  make_dir(out_dir);
  auto filter = make_or_throw(filter_name, config, north);
  std::vector<eval::TrialResult> results;
  std::cerr << "poise eval broad: " << files.size() << " trial(s), estimates -> "
            << (std::filesystem::path(out_dir) / "<stem>.csv").string() << "\n";
  Progress progress("poise eval broad", files.size());
  for (size_t i = 0; i < files.size(); ++i) {
    progress.update(i, files[i]);
    const eval::BroadTrial trial = load_trials({files[i]}, transform).front();
    size_t estimated = 0;
    const eval::TrialEstimates est = eval::run_filter_estimates(*filter, trial, &estimated);
    const std::string csv = (std::filesystem::path(out_dir) / (trial.stem + ".csv")).string();
    eval::write_estimate_csv(csv, est, trial.rate_hz);
    results.push_back(score(trial, est.q, estimated));
    results.back().nees = eval::broad_consistency(est, trial);
    std::ostringstream note;  // only what needs saying: the figures are in the table
    if (trial.invalid_reference_rows > 0) {
      note << trial.stem << ": " << trial.invalid_reference_rows
           << " reference rows are not unit quaternions: not scored";
    }
    if (estimated == 0) {
      note << (note.tellp() > 0 ? "; " : "") << no_estimate_note(trial.stem);
    } else if (!results.back().errors.scored()) {
      note << (note.tellp() > 0 ? "; " : trial.stem + ": ") << "no scorable samples (movement with a valid reference)";
    }
    if (note.tellp() > 0) {
      progress.note(note.str());
    }
  }
  progress.finish();
  eval::print_table(std::cout, filter_name, results);
  if (eval::group_means(results).unscored.size() == results.size()) {
    throw Error("no trial has scorable samples (samples with movement and a valid reference quaternion)");
  }
}

struct GridOptions {
  std::vector<std::string> grid;
  int folds = 0;  ///< 0 = leave one trial out
  TrialTransform trials;
};

/// Runs every grid candidate on every trial, prints the in-sample and cross-validated figures,
/// and returns the cross-validation (with the candidates) for `poise tune`.
// not split: the grid's three phases (run every candidate on every trial, fold, print) share the
// per-candidate results table.
std::pair<eval::CrossValidation, std::vector<eval::Overrides>> run_grid(
    const std::string& filter_name, const std::string& config, const std::string& out_dir,
    const std::vector<std::string>& files, const GridOptions& g, bool broad, const NorthReference& north) {
  make_dir(out_dir);
  std::vector<eval::GridAxis> axes;
  try {
    axes = eval::parse_grid(g.grid);
  } catch (const std::exception& e) {
    throw Error(e.what());
  }
  const std::vector<eval::Overrides> candidates = eval::grid_points(axes);
  if (config.empty() && broad) {
    // Candidates are written on top of the base file; without one they would be the built-in
    // defaults plus the grid keys, which is not what a filter with its own BROAD default runs.
    for (const auto& entry : eval::registered_filters()) {
      if (entry.name == filter_name && entry.broad_default) {
        throw Error("--grid with filter '" + filter_name +
                    "' needs --config BASE.yaml (its figures on BROAD use a configuration other than the "
                    "built-in defaults; the BROAD bases are config/filters/parallel_kf_broad.yaml and "
                    "selective_ekf_broad.yaml)");
      }
    }
  }
  if (g.folds != 0 && (g.folds < 2 || g.folds > static_cast<int>(files.size()))) {
    throw Error("--folds must be between 2 and the number of trials (" + std::to_string(files.size()) +
                "); 0 = leave one trial out");
  }
  std::cerr << "loading " << files.size() << " trial(s) ...\n";
  const std::vector<eval::BroadTrial> trials = load_trials(files, g.trials);
  const std::string cand_dir = (std::filesystem::path(out_dir) / "candidates").string();
  make_dir(cand_dir);
  const std::string table_path = (std::filesystem::path(out_dir) / "grid_results.csv").string();
  std::ofstream table(table_path);
  if (!table) {
    throw Error("cannot write '" + table_path + "'");
  }
  table << "candidate,overrides,trial,total_deg,heading_deg,inclination_deg\n";
  std::vector<std::vector<eval::TrialResult>> by_candidate;
  Progress progress("poise eval broad --grid", candidates.size() * trials.size());
  for (size_t c = 0; c < candidates.size(); ++c) {
    if (stop_requested()) {
      throw Error("interrupted");
    }
    std::string cfg = config;
    if (!candidates[c].empty()) {
      cfg = (std::filesystem::path(cand_dir) / ("candidate_" + std::to_string(c) + ".yaml")).string();
      try {
        eval::write_config_with_overrides(config, candidates[c], cfg);
      } catch (const std::exception& e) {
        throw Error(e.what());
      }
    }
    auto filter = make_or_throw(filter_name, cfg, north);
    std::vector<eval::TrialResult> rs;
    for (const auto& trial : trials) {
      progress.update(c * trials.size() + rs.size(), "candidate " + std::to_string(c + 1) + ", " + trial.stem);
      size_t estimated = 0;
      const auto q = eval::run_filter(*filter, trial, &estimated);
      rs.push_back(score(trial, q, estimated));
      if (estimated == 0) {
        progress.note("[candidate " + std::to_string(c + 1) + "] " + no_estimate_note(trial.stem));
      }
      table << c << ",\"" << eval::describe(candidates[c]) << "\"," << rs.back().stem << std::fixed
            << std::setprecision(4) << "," << rs.back().errors.total_deg << "," << rs.back().errors.heading_deg
            << "," << rs.back().errors.inclination_deg << "\n";
    }
    const eval::GroupMeans m = eval::group_means(rs);
    progress.note("[candidate " + std::to_string(c + 1) + "/" + std::to_string(candidates.size()) + "] " +
                  eval::describe(candidates[c]) + ": undisturbed" +
                  eval::format_mean_figure(m.undisturbed.total_deg, m.n_undisturbed, 7) + ", disturbed" +
                  eval::format_mean_figure(m.disturbed.total_deg, m.n_disturbed, 7) + " deg");
    by_candidate.push_back(std::move(rs));
  }
  progress.finish();
  table.close();  // flushes: a full disk shows here
  if (!table) {
    throw Error("error while writing '" + table_path + "' (disk full or device refused the data)");
  }
  if (eval::group_means(by_candidate.front()).unscored.size() == trials.size()) {
    throw Error("no trial has scorable samples (samples with movement and a valid reference quaternion)");
  }
  const eval::CrossValidation cv = eval::cross_validate(by_candidate, g.folds);
  const eval::GroupMeans in = eval::group_means(cv.in_sample);
  const eval::GroupMeans out = eval::group_means(cv.cross_validated);
  std::cout << "filter " << filter_name << (config.empty() ? "" : " (base " + config + ")") << ", "
            << candidates.size() << " candidate(s), " << trials.size() << " trial(s), "
            << (g.folds == 0 ? "leave-one-trial-out" : std::to_string(cv.folds) + "-fold")
            << " cross-validation\n"
            << "choice: the candidate with the lowest mean of the undisturbed and disturbed mean total RMSE "
               "on the trials outside the held-out fold\n\n";
  std::cout << std::left << std::setw(44) << "trial" << std::right << std::setw(10) << "in-sample"
            << std::setw(10) << "cross-val" << "  chosen without this trial's fold\n";
  for (size_t t = 0; t < trials.size(); ++t) {
    std::cout << std::left << std::setw(44) << trials[t].stem
              << eval::format_trial_figure(cv.in_sample[t].errors, cv.in_sample[t].errors.total_deg, 10)
              << eval::format_trial_figure(cv.cross_validated[t].errors, cv.cross_validated[t].errors.total_deg, 10)
              << "  " << eval::describe(candidates[cv.choice_per_trial[t]])
              << (cv.in_sample[t].errors.scored() ? "" : "  (no scorable samples: excluded)") << "\n";
  }
  auto row = [&](const std::string& label, const eval::GroupMeans& m) {
    const int n_all = m.n_undisturbed + m.n_disturbed;
    std::cout << std::left << std::setw(26) << label << eval::format_mean_figure(m.undisturbed.total_deg, m.n_undisturbed, 10)
              << eval::format_mean_figure(m.undisturbed.inclination_deg, m.n_undisturbed, 10)
              << eval::format_mean_figure(m.disturbed.total_deg, m.n_disturbed, 10)
              << eval::format_mean_figure(m.disturbed.inclination_deg, m.n_disturbed, 10)
              << eval::format_mean_figure(m.all.total_deg, n_all, 10)
              << eval::format_mean_figure(m.all.inclination_deg, n_all, 10) << "\n";
  };
  std::cout << "\nmean RMSE, deg (" << in.n_undisturbed << " undisturbed, " << in.n_disturbed << " disturbed"
            << (in.unscored.empty() ? "" : ", " + std::to_string(in.unscored.size()) + " without scorable samples excluded")
            << ")\n"
            << std::left << std::setw(26) << "" << std::right << std::setw(20) << "undisturbed" << std::setw(20)
            << "disturbed" << std::setw(20) << "all" << "\n"
            << std::left << std::setw(26) << "" << std::right << std::setw(10) << "total" << std::setw(10) << "incl"
            << std::setw(10) << "total" << std::setw(10) << "incl" << std::setw(10) << "total" << std::setw(10)
            << "incl" << "\n";
  row("in-sample", in);
  row("cross-validated", out);
  std::cout << "\nin-sample choice: " << eval::describe(candidates[cv.in_sample_choice]) << "\n"
            << "per-candidate, per-trial figures: " << table_path
            << "\n";
  return {cv, candidates};
}

std::string default_broad_dir() {
  if (const char* env = std::getenv("POISE_SHARED_DIR"); env != nullptr && *env != '\0') {
    return std::string(env) + "/broad";
  }
  return "../shared/broad";
}

void run_bench(const std::string& file_arg, const std::string& broad_dir, int repeats,
               const std::vector<std::string>& only, const NorthReference& north) {
  install_stop_handlers();
  std::string file = file_arg;
  if (file.empty() && std::filesystem::is_directory(broad_dir)) {
    std::vector<std::string> found;
    for (const auto& e : std::filesystem::directory_iterator(broad_dir)) {
      if (e.path().extension() == ".hdf5") {
        found.push_back(e.path().string());
      }
    }
    std::sort(found.begin(), found.end());
    if (!found.empty()) {
      file = found.front();
    }
  }
  eval::BroadTrial trial;
  if (!file.empty()) {
    try {
      trial = eval::load_broad(file);
    } catch (const std::exception& e) {
      throw Error(e.what());
    }
    std::cout << "input: BROAD trial " << file << " (" << trial.size() << " samples at "
              << trial.rate_hz << " Hz)\n";
  } else {
    // No BROAD data: the simulator's random_motion scenario at BROAD's rate.
    sim::SensorSimulator s(sim::make_scenario("random_motion", 2000.0 / 7.0, 1));
    trial.stem = "sim_random_motion";
    trial.rate_hz = s.config().rate_hz;
    while (!s.done()) {
      const sim::SimSample x = s.next();
      trial.gyr_rps.push_back(x.imu.gyro_rps);
      trial.acc_mps2.push_back(x.imu.accel_mps2);
      trial.mag_ut.push_back(x.imu.mag_ut);
      trial.opt_quat_wxyz.push_back(Eigen::Vector4d(x.truth.q_world_body.w(), x.truth.q_world_body.x(),
                                                    x.truth.q_world_body.y(), x.truth.q_world_body.z()));
      trial.movement.push_back(1);
    }
    std::cout << "input: BROAD not found in '" << broad_dir
              << "': using the simulator (scenario random_motion, " << trial.size() << " samples at "
              << trial.rate_hz << " Hz)\n";
  }
  std::vector<ImuSample> samples(trial.size());
  for (size_t k = 0; k < trial.size(); ++k) {
    samples[k] = trial.sample(k);
  }
  std::cout << "single thread, best of " << repeats
            << " runs; per sample: update() + q_world_body(); cpu = thread CPU time (what the filter costs),"
               " wall = elapsed (inflated when other processes share the cores)\n";
  std::cout << std::left << std::setw(22) << "filter" << std::right << std::setw(16) << "cpu ns/sample"
            << std::setw(16) << "wall ns/sample" << "\n";
  for (const auto& entry : eval::registered_filters()) {
    if (!only.empty() && std::find(only.begin(), only.end(), entry.name) == only.end()) {
      continue;
    }
    auto f = eval::with_north(entry.broad_default ? entry.broad_default() : entry.factory(""), north);
    double sink = 0.0;
    const BenchFigures best = best_of_runs(static_cast<int>(samples.size()), repeats, [&] {
      f->reset();
      if (auto* inputs = dynamic_cast<eval::TrialInputs*>(f.get())) {
        inputs->begin_trial(trial);  // e.g. selective_vision30: vision synthesised from the reference
      }
      return [&](int i) {
        f->update(samples[static_cast<size_t>(i)]);
        sink += f->q_world_body().w();
      };
    });
    const double best_cpu = best.cpu_ns_per_sample;
    const double best_wall = best.wall_ns_per_sample;
    std::cout << std::left << std::setw(22) << entry.name << std::right << std::fixed << std::setprecision(1)
              << std::setw(16) << best_cpu << std::setw(16) << best_wall << (sink == 12345.0 ? " " : "") << "\n";
  }
}

/// `poise calibrate imu-delay`: the IMU's group delay against each trial's optical reference.
int run_imu_delay(const std::vector<std::string>& files, int window) {
  std::vector<double> delays_ms;
  std::cout << std::left << std::setw(48) << "trial" << std::right << std::setw(12) << "delay ms"
            << std::setw(10) << "samples" << std::setw(14) << "rms@delay" << std::setw(12) << "rms@0"
            << std::setw(10) << "windows" << "\n";
  Progress progress("poise calibrate imu-delay", files.size());
  for (std::size_t i = 0; i < files.size(); ++i) {
    const std::string& path = files[i];
    progress.update(i, path);
    if (stop_requested()) {
      break;
    }
    eval::BroadTrial trial;
    try {
      trial = eval::load_broad(path);
    } catch (const std::exception& e) {
      throw Error(std::string(e.what()));
    }
    eval::ImuDelayOptions o;
    o.rate_hz = trial.rate_hz;
    o.window_samples = window;
    const eval::ImuDelayEstimate est = eval::estimate_imu_delay(trial.gyr_rps, trial.opt_quat_wxyz, trial.movement, o);
    progress.hide();  // the row goes to stdout, perhaps the same terminal
    std::cout << std::left << std::setw(48) << trial.stem << std::right << std::fixed;
    if (!est.ok) {
      std::cout << "  no estimate: " << est.why << "\n";
      continue;
    }
    std::cout << std::setprecision(3) << std::setw(12) << est.delay_s * 1e3 << std::setprecision(2)
              << std::setw(10) << est.delay_samples << std::setprecision(3) << std::setw(14)
              << est.rms_at_delay_deg << std::setw(12) << est.rms_at_zero_deg << std::setw(10) << est.windows
              << "\n";
    delays_ms.push_back(est.delay_s * 1e3);
  }
  progress.finish();
  if (delays_ms.empty()) {
    std::cerr << "poise calibrate imu-delay: no trial gave an estimate (needs motion with a valid reference)\n";
    return 1;
  }
  std::sort(delays_ms.begin(), delays_ms.end());
  const size_t m = delays_ms.size();
  const double median = m % 2 == 1 ? delays_ms[m / 2] : 0.5 * (delays_ms[m / 2 - 1] + delays_ms[m / 2]);
  std::cout << std::setprecision(3) << "\nmedian over " << m << " trials: " << median << " ms (range "
            << delays_ms.front() << " to " << delays_ms.back() << ")\n"
            << "selective EKF parameter: imu_delay_s: " << std::setprecision(5) << median * 1e-3 << "\n";
  return 0;
}

}  // namespace

// not split: the options and help of `calibrate imu-delay`, `eval broad`, `tune` and `bench filters`
// in the order --help prints them.
void register_eval_cli(CLI::App& app) {
  CLI::App* calibrate = subcommand_group(app, "calibrate", "Guided sensor calibration");
  CLI::App* delay = calibrate->add_subcommand(
      "imu-delay", "IMU group delay against an optical reference (BROAD-layout HDF5: imu_gyr, opt_quat, movement)");
  auto delay_files = std::make_shared<std::vector<std::string>>();
  auto window = std::make_shared<int>(20);
  delay->add_option("files", *delay_files, "HDF5 recordings with gyro and reference")->required()->check(CLI::ExistingFile);
  delay->add_option("--window", *window, "Gyro integration window, samples")->check(CLI::Range(2, 1000))->capture_default_str();
  delay->callback([=]() {
    install_stop_handlers();
    const int rc = run_imu_delay(*delay_files, *window);
    if (rc != 0) {
      throw ExitCode{rc};
    }
  });

  CLI::App* eval_group = subcommand_group(app, "eval", "Evaluate estimators on recorded data");
  CLI::App* broad = eval_group->add_subcommand(
      "broad", "Run an attitude filter over BROAD HDF5 trials; write DIR/<stem>.csv and print the RMSE table");
  auto filter = std::make_shared<std::string>("parallel_kf");
  auto config = std::make_shared<std::string>();
  auto out = std::make_shared<std::string>();
  auto files = std::make_shared<std::vector<std::string>>();
  broad->add_option("--filter", *filter, "Filter name (see `poise bench filters --list`)")
      ->capture_default_str();
  broad->add_option("--config", *config, "YAML parameter file for the filter (config/filters/...)")
      ->check(CLI::ExistingFile);
  CLI::Option* out_dir = add_out_dir_option(broad, out.get(), "the per-trial CSV files (required)", false);
  require_one_of(broad, {out_dir, add_deprecated_alias(broad, "--out", "--out-dir", out.get())});
  broad->add_option("files", *files, "BROAD .hdf5 files")->required()->check(CLI::ExistingFile);
  auto grid = std::make_shared<GridOptions>();
  broad->add_option("--grid", grid->grid,
                    "Parameter to choose, KEY=V1,V2,... (repeatable; YAML key of the filter, dotted for nested "
                    "fields). Every combination runs on every trial; prints in-sample and cross-validated means")
      ->allow_extra_args(false)
      ->type_name("KEY=VALUES");
  broad->add_option("--folds", grid->folds,
                    "Cross-validation folds for --grid (trial i is in fold i mod K; 0 = leave one trial out)")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  broad->add_option("--every", grid->trials.every,
                    "Use every N-th sample of each trial as recorded (a lower-rate sensor: 3 = 95.2 Hz, 7 = 40.8 Hz "
                    "from BROAD's 285.7 Hz)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  broad->add_option("--attach-magnet-ut", grid->trials.magnet_ut,
                    "Emulate a magnet attached to the sensor: from --attach-magnet-at of each trial on, a constant "
                    "body-frame offset of this many uT (direction drawn from the trial's number) is added to the "
                    "magnetometer (0 = none)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  broad->add_option("--attach-magnet-at", grid->trials.magnet_at,
                    "With --attach-magnet-ut: the fraction of each trial's duration after which the magnet is on")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  auto sets = std::make_shared<std::vector<std::string>>();
  add_north_set_option(broad, sets.get());
  broad->callback([=]() {
    install_stop_handlers();
    const NorthReference north = north_option(*sets, "poise eval broad");
    if (grid->grid.empty()) {
      if (grid->folds != 0) {
        std::cerr << "poise eval broad: --folds without --grid: no parameter is chosen, so the in-sample "
                     "figure below is also the cross-validated one\n";
      }
      run_eval(*filter, *config, *out, *files, north, grid->trials);
      return;
    }
    run_grid(*filter, *config, *out, *files, *grid, true, north);
  });

  CLI::App* tune = app.add_subcommand(
      "tune", "Choose filter parameters on your own recordings with ground truth (BROAD-layout HDF5) by "
              "cross-validation, and write the chosen YAML");
  auto t_filter = std::make_shared<std::string>("parallel_kf");
  auto t_config = std::make_shared<std::string>();
  auto t_out = std::make_shared<std::string>();
  auto t_write = std::make_shared<std::string>();
  auto t_files = std::make_shared<std::vector<std::string>>();
  auto t_grid = std::make_shared<GridOptions>();
  tune->add_option("--filter", *t_filter, "Filter name (see `poise bench filters --list`)")->capture_default_str();
  tune->add_option("--config", *t_config, "Base YAML parameter file (default: the filter's defaults)")
      ->check(CLI::ExistingFile);
  tune->add_option("--grid", t_grid->grid, "Parameter to choose, KEY=V1,V2,... (repeatable)")
      ->required()
      ->allow_extra_args(false)
      ->type_name("KEY=VALUES");
  tune->add_option("--folds", t_grid->folds, "Cross-validation folds (0 = leave one recording out)")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  CLI::Option* t_out_dir = add_out_dir_option(tune, t_out.get(), "working files (candidate configs, per-candidate figures) (required)", false);
  require_one_of(tune, {t_out_dir, add_deprecated_alias(tune, "--out", "--out-dir", t_out.get())});
  CLI::Option* t_output = add_output_file_option(tune, t_write.get(), "the chosen YAML (required)", false);
  require_one_of(tune, {t_output, add_deprecated_alias(tune, "--write", "-o/--output", t_write.get())});
  tune->add_option("files", *t_files,
                   "Recordings: HDF5 with imu_gyr (rad/s), imu_acc (m/s^2), imu_mag (uT), opt_quat (reference "
                   "q_world_body ENU [w,x,y,z]), movement (scored samples), attribute sampling_rate (Hz); "
                   "trial numbers >= 24 in the file name count as disturbed")
      ->required()
      ->check(CLI::ExistingFile);
  auto t_sets = std::make_shared<std::vector<std::string>>();
  add_north_set_option(tune, t_sets.get());
  tune->callback([=]() {
    install_stop_handlers();
    const NorthReference north = north_option(*t_sets, "poise tune");
    const auto [cv, candidates] = run_grid(*t_filter, *t_config, *t_out, *t_files, *t_grid, false, north);
    const eval::GroupMeans in_means = eval::group_means(cv.in_sample);
    const eval::GroupMeans cv_means = eval::group_means(cv.cross_validated);
    std::ostringstream header;
    header << std::fixed << std::setprecision(3) << "written by poise tune: filter " << *t_filter << ", "
           << t_files->size() << " recording(s)\nchosen: " << eval::describe(candidates[cv.in_sample_choice])
           << "\nmean total RMSE deg, in-sample " << in_means.all.total_deg << ", cross-validated " << cv_means.all.total_deg
           << " (expect the cross-validated figure on new recordings)";
    try {
      eval::write_config_with_overrides(*t_config, candidates[cv.in_sample_choice], *t_write, header.str());
    } catch (const std::exception& e) {
      throw Error(e.what());
    }
    std::cout << "wrote " << *t_write << "\n";
  });

  CLI::App* bench_group = subcommand_group(app, "bench", "Benchmarks (figures printed, not asserted)");
  CLI::App* bench = bench_group->add_subcommand(
      "filters", "ns per sample of each attitude filter on a BROAD trial (simulator if BROAD is absent)");
  auto file = std::make_shared<std::string>();
  auto dir = std::make_shared<std::string>(default_broad_dir());
  auto repeats = std::make_shared<int>(3);
  auto list = std::make_shared<bool>(false);
  auto only = std::make_shared<std::vector<std::string>>();
  bench->add_option("--file", *file, "BROAD .hdf5 trial (default: the first one in --broad-dir)");
  bench->add_option("--broad-dir", *dir, "Directory searched for BROAD trials")->capture_default_str();
  bench->add_option("--repeat", *repeats, "Runs per filter (best is reported)")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  bench->add_flag("--list", *list, "List the registered filters and exit");
  bench->add_option("--filter", *only, "Only these filters (repeatable; default: all)");
  auto b_sets = std::make_shared<std::vector<std::string>>();
  add_north_set_option(bench, b_sets.get());
  bench->callback([=]() {
    if (*list) {
      std::cout << "filters:" << filter_list() << "\n";
      return;
    }
    run_bench(*file, *dir, *repeats, *only, north_option(*b_sets, "poise bench filters"));
  });
}

}  // namespace poise::cli
