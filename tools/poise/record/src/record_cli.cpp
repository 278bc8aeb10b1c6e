// `poise info`, `poise record`, `poise replay`, `poise bench record`, `poise bench replay`.
#include "poise/cli/common.h"
#include "poise/cli/progress.h"
#include "poise/dds/participant.h"
#include "poise/eval/filter_registry.h"
#include "poise/eval/north_filter.h"
#include "poise/core/yaml_params.h"
#include "poise/nodes/estimator_step.h"
#include "poise/nodes/register.h"
#include "poise/process/compare.h"

#include <sys/stat.h>
#include "poise/process/process.h"
#include "poise/record/info.h"
#include "poise/record/recorder.h"
#include "poise/record/replayer.h"
#include "poise/runtime/host.h"
#include "poise/runtime/utc_date.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>

namespace poise::cli {

namespace {

struct InfoArgs {
  std::string file;
  bool verify = false;
};

struct RecordArgs {
  std::string output;
  std::vector<std::string> topics;
  bool all = false;
  double duration_s = 0.0;
  double split_mb = 0.0;
  std::string compression = "none";
  int domain = 0;
  std::string profile;
};

struct ReplayArgs {
  std::string file;
  double rate = 1.0;
  double start_s = -1.0;
  double end_s = -1.0;
  std::vector<std::string> topics;
  bool loop = false;
  bool afap = false;
  double wait_s = 1.0;
  int domain = 0;
  std::string profile;
  bool allow_damaged = false;
};

struct ProcessArgs {
  std::string file;
  std::string output;
  std::string host;
  std::vector<std::string> filters;
  std::vector<std::string> sets;
  std::string imu_topic;
  std::string order = "stamp";
  double start_s = 0.0;
  double end_s = std::numeric_limits<double>::infinity();
  std::vector<double> window;  // FROM, TO: seconds from each processed series' first estimate
  bool compare = true;
  bool allow_damaged = false;
};

// Damaged input (incomplete file: cut short, no footer or summary; unreadable chunks): the
// readable part was used and reported; exit code 3 (as `poise info`) unless the user accepts
// damaged input (issue 33: a file cut short exited 0 although the help says 3).
void refuse_damaged(const char* command, bool damaged, bool allow_damaged) {
  if (damaged && !allow_damaged) {
    std::cerr << "poise " << command
              << ": exit code 3: the input is damaged or incomplete (see above); --allow-damaged accepts it\n";
    throw ExitCode{3};
  }
}

std::string known_filters() {
  std::string known;
  for (const auto& e : eval::registered_filters()) {
    known += (known.empty() ? "" : ", ") + e.name;
  }
  return known;
}

std::unique_ptr<AttitudeFilter> make_offline_filter(const std::string& name, const std::string& config) {
  try {
    return eval::make_filter(name, config);
  } catch (const std::exception& e) {
    throw Error("filter '" + name + "': " + e.what());
  }
}

/// --set for `poise process`: NAME.key=VALUE changes the host's component NAME; for a --filter
/// NAME, and KEY=VALUE without NAME for every --filter filter, the node keys (imu_sensor_id, ...:
/// filter_node_params) and the north keys (eval::north_from_sets).
struct ProcessSets {
  std::vector<std::string> host;
  std::vector<std::string> every_filter;
  std::map<std::string, std::vector<std::string>> per_filter;
};

ProcessSets split_process_sets(const ProcessArgs& a) {
  ProcessSets out;
  std::vector<std::string>& host_sets = out.host;
  std::vector<std::string>& every_filter_sets = out.every_filter;
  std::map<std::string, std::vector<std::string>>& filter_sets = out.per_filter;
  std::vector<std::string> filter_names;
  for (const std::string& f : a.filters) {
    filter_names.push_back(f.substr(0, f.find('=')));
  }
  for (const std::string& set : a.sets) {
    const size_t eq = set.find('=');
    const size_t dot = set.find('.');
    if (dot == std::string::npos || dot > eq) {
      every_filter_sets.push_back(set);
    } else if (std::find(filter_names.begin(), filter_names.end(), set.substr(0, dot)) != filter_names.end()) {
      filter_sets[set.substr(0, dot)].push_back(set.substr(dot + 1));
    } else {
      host_sets.push_back(set);
    }
  }
  if (!every_filter_sets.empty() && a.filters.empty()) {
    throw Error("--set " + every_filter_sets.front() +
                    ": KEY=VALUE without NAME applies to the --filter filters; for a component of the host "
                    "file write NAME.key=VALUE",
                kUsageExitCode);
  }
  if (!host_sets.empty() && a.host.empty()) {
    throw Error("--set " + host_sets.front() + ": NAME.key=VALUE changes a component of the host file (give "
                    "--host HOST.yaml) or a --filter NAME (" +
                    (filter_names.empty() ? std::string("none given") : "given: " + [&] {
                      std::string n;
                      for (const auto& f : filter_names) {
                        n += (n.empty() ? "" : ", ") + f;
                      }
                      return n;
                    }()) + ")",
                kUsageExitCode);
  }
  return out;
}

/// The estimator components of the host file (with its --set changes), labelled "name (type)".
void add_host_components(const ProcessArgs& a, const std::vector<std::string>& host_sets,
                         record::ProcessOptions& o, std::vector<record::ProcessComponent>& components,
                         std::vector<std::string>& labels) {
  runtime::HostSpec host;
  try {
    host = runtime::load_host_file(a.host);
  } catch (const std::exception& e) {
    throw Error(e.what());
  }
  try {
    runtime::apply_component_sets(host_sets, host);
  } catch (const std::invalid_argument& e) {
    throw Error(e.what(), kUsageExitCode);
  }
  o.topics = host.topics;
  for (const auto& c : host.components) {
    std::unique_ptr<nodes::EstimatorStep> step;
    nodes::NodeParams params;
    try {
      step = nodes::make_estimator_step(c);
      if (step) {
        params = nodes::node_params(c);
      }
    } catch (const std::exception& e) {
      throw Error(e.what());
    }
    if (!step) {
      std::cerr << "poise process: component '" << c.name << "' (" << c.type
                << ") is not an estimator: skipped\n";
      continue;
    }
    labels.push_back(c.name + " (" + c.type + ")");
    components.push_back({std::move(step), params});
  }
}

/// A --filter's node keys (nodes::NodeParams::keys(): imu_sensor_id, diagnostics_*, input_*),
/// taken out of its --set assignments and checked as a host file's component params are; the rest
/// (the north keys) stay in `sets`. Throws Error (usage) naming the assignment.
nodes::NodeParams filter_node_params(const std::string& name, std::vector<std::string>& sets) {
  const std::vector<std::string>& keys = nodes::NodeParams::keys();
  runtime::ComponentSpec spec{name, name, YAML::Node(YAML::NodeType::Map), "--set for filter '" + name + "'"};
  std::vector<std::string> rest;
  for (const std::string& set : sets) {
    const size_t eq = set.find('=');
    const std::string key = set.substr(0, eq);
    if (eq == std::string::npos || std::find(keys.begin(), keys.end(), key) == keys.end()) {
      rest.push_back(set);
      continue;
    }
    if (spec.params[key]) {
      throw Error("--set " + set + ": '" + key + "' is given twice for filter '" + name + "'", kUsageExitCode);
    }
    try {
      spec.params[key] = parse_yaml(set.substr(eq + 1), "--set " + set);
    } catch (const std::exception& e) {
      throw Error(e.what(), kUsageExitCode);
    }
  }
  sets = rest;
  try {
    return nodes::node_params(spec);
  } catch (const std::exception& e) {
    throw Error(e.what(), kUsageExitCode);
  }
}

/// The --filter NAME[=CONFIG] filters, each with its node keys and its north from --set.
void add_filter_components(const ProcessArgs& a, ProcessSets& sets_in,
                           std::vector<record::ProcessComponent>& components, std::vector<std::string>& labels) {
  const std::vector<std::string>& every_filter_sets = sets_in.every_filter;
  std::map<std::string, std::vector<std::string>>& filter_sets = sets_in.per_filter;
  for (const std::string& f : a.filters) {
    const size_t eq = f.find('=');
    const std::string name = f.substr(0, eq);
    const std::string config = eq == std::string::npos ? std::string() : f.substr(eq + 1);
    std::vector<std::string> sets = every_filter_sets;
    sets.insert(sets.end(), filter_sets[name].begin(), filter_sets[name].end());
    const nodes::NodeParams params = filter_node_params(name, sets);
    NorthReference north;
    try {
      north = eval::north_from_sets(sets, runtime::utc_today(), nodes::NodeParams::keys());
    } catch (const std::invalid_argument& e) {
      throw Error("filter '" + name + "': " + e.what(), kUsageExitCode);
    }
    labels.push_back(name + " (--filter" + (north.true_north ? ", " + std::string(north.frame_id()) : "") + ")");
    components.push_back({record::filter_step({name, make_offline_filter(name, config), north}), params});
  }
}

/// What was read, run and written, on stderr.
void print_process_summary(const ProcessArgs& a, const record::ProcessOptions& o, record::ProcessStats& stats,
                           const std::vector<std::string>& labels) {
  if (!stats.input_problems.empty()) {
    std::cerr << "poise process: the input is "
              << (stats.input_damaged() ? "damaged (" + std::to_string(stats.corrupt_in_file +
                                                                       stats.damaged_chunks) +
                                              " corrupt part(s) skipped)"
                                        : std::string("incomplete"))
              << "; processed the readable part:\n";
    for (const auto& p : stats.input_problems) {
      std::cerr << "  " << p << "\n";
    }
  }
  std::cerr << "poise process: " << stats.input_messages << " messages, " << stats.imu_samples
            << " IMU samples on '" << o.topics.imu << "', " << stats.vision_samples
            << " vision poses, " << stats.vehicle_inputs << " vehicle inputs (" << stats.undecodable
            << " malformed, skipped), in " << (a.order == "recorded" ? "recorded" : "stamp")
            << " order (at most " << stats.reorder_window << " input(s) held to reorder) -> " << a.output << "\n";
  if (stats.imu_gaps > 0) {
    std::cerr << "poise process: the recorded '" << o.topics.imu << "' has " << stats.imu_gaps
              << " gap(s) in header.seq (" << stats.imu_missing
              << " sample(s) missing): the live components may have processed samples the "
                 "recording lacks, so estimates after a gap can differ from live\n";
  }
  for (const auto& d : stats.undecodable_details) {
    std::cerr << "  skipped " << d << "\n";
  }
  for (const auto& n : stats.imu_delay_notes) {
    std::cerr << "  " << n << "\n";
  }
  if (stats.undecodable > stats.undecodable_details.size()) {
    std::cerr << "  ... and " << stats.undecodable - stats.undecodable_details.size()
              << " more malformed payload(s)\n";
  }
  for (size_t i = 0; i < labels.size(); ++i) {
    const std::string name = labels[i].substr(0, labels[i].find(' '));
    std::cerr << "  " << labels[i] << ": " << stats.estimates[name] << " estimates, "
              << stats.rejected[name] << " samples rejected, " << stats.diagnostics[name]
              << " diagnostics\n";
  }
  for (const auto& [topic, n] : stats.per_topic) {
    std::cerr << "  " << topic << ": " << n << " messages\n";
  }
}

void run_process(const ProcessArgs& a) {
  std::vector<record::ProcessComponent> components;
  std::vector<std::string> labels;  // "name (type)" per component, for the summary
  record::ProcessOptions o;
  if (!(a.end_s > a.start_s)) {
    throw Error("--end must be later than --start", kUsageExitCode);
  }
  record::CompareWindow window;
  if (!a.window.empty()) {
    if (a.window.size() != 2 || !(a.window[1] > a.window[0])) {
      throw Error("--window FROM,TO needs two numbers with TO later than FROM (seconds)", kUsageExitCode);
    }
    window.from_s = a.window[0];
    window.to_s = a.window[1];
  }
  o.start_s = a.start_s;
  o.end_s = a.end_s;
  ProcessSets sets = split_process_sets(a);
  if (!a.host.empty()) {
    add_host_components(a, sets.host, o, components, labels);
  }
  add_filter_components(a, sets, components, labels);
  if (components.empty()) {
    throw Error("nothing to run: give --host HOST.yaml with estimator components (" +
                [] {
                  std::string types;
                  for (const auto& t : nodes::estimator_step_types()) {
                    types += (types.empty() ? "" : ", ") + t;
                  }
                  return types;
                }() +
                "), or --filter NAME[=CONFIG.yaml] (known: " + known_filters() + ")");
  }
  if (!a.imu_topic.empty()) {
    o.topics.imu = a.imu_topic;
  }
  o.input = a.file;
  o.output = a.output;
  o.order = a.order == "recorded" ? record::ProcessOrder::kRecorded : record::ProcessOrder::kStamp;
  Progress::Options shown;
  shown.counts = false;  // units of three passes: the percentage says it
  Progress progress("poise process", 100, shown);
  o.progress = [&progress](uint64_t done, uint64_t total) { progress.update(done * 100 / total); };
  record::ProcessStats stats;
  try {
    stats = record::process_recording(o, components);
    progress.finish();
  } catch (const record::ReadError& e) {
    throw Error(e.what());
  } catch (const record::WriteError& e) {
    throw Error(e.what());
  }
  print_process_summary(a, o, stats, labels);
  if (stats.imu_samples == 0) {
    throw Error("no ImuSample messages on topic '" + o.topics.imu +
                "' in the recording (use --imu-topic; `poise info` lists the topics)");
  }
  struct stat out_stat {};
  if (a.compare && ::stat(a.output.c_str(), &out_stat) == 0 && !S_ISREG(out_stat.st_mode)) {
    // written in place (a device such as /dev/null, a FIFO): nothing to read back
    std::cerr << "poise process: no comparison: the output '" << a.output << "' is not a regular file\n";
  } else if (a.compare) {
    try {
      std::cout << record::format_comparison(record::compare_processed(a.output, o.output_prefix, window));
    } catch (const record::ReadError& e) {
      throw Error(std::string("comparison: ") + e.what());
    }
  }
  refuse_damaged("process", stats.input_damaged() || !stats.input_complete, a.allow_damaged);
}

void run_info(const InfoArgs& a) {
  try {
    record::McapReader reader = record::McapReader::open_file(a.file);
    if (a.verify) {
      reader.verify();
    }
    std::cout << record::format_info(reader, a.file);
    if (!reader.report().complete) {
      throw ExitCode{3};
    }
  } catch (const record::ReadError& e) {
    throw Error(std::string(e.what()));
  }
}

void run_record(const RecordArgs& a) {
  record::RecorderOptions o;
  o.output = a.output;
  o.topics = a.topics;
  o.all = a.all;
  o.domain = a.domain;
  o.participant_profile = a.profile;
  o.duration_s = a.duration_s;
  o.split_size_bytes = static_cast<uint64_t>(a.split_mb * 1024.0 * 1024.0);
  if (a.compression == "zstd") {
    if (!record::zstd_available()) {
      throw Error("--compression zstd: this build has no libzstd (install libzstd-dev, rebuild)");
    }
    o.writer.compression = record::Compression::kZstd;
  }
  install_stop_handlers();
  o.should_stop = [] { return stop_requested(); };
  record::RecorderStats stats;
  try {
    record::Recorder recorder(o);
    std::cerr << "poise record: waiting for publishers on domain " << a.domain
              << (a.all ? " (all poise topics)" : "") << "; Ctrl-C to stop\n";
    stats = recorder.run();
  } catch (const record::WriteError& e) {
    throw Error(e.what());
  } catch (const dds::DdsError& e) {
    throw Error(e.what());
  }
  std::cerr << "poise record: " << stats.written << " messages written to";
  for (const auto& f : stats.files) {
    std::cerr << " " << f;
  }
  std::cerr << " in " << stats.elapsed_s << " s\n";
  for (const auto& [topic, t] : stats.topics) {
    std::cerr << "  " << topic << " (" << t.type << "): received " << t.received << ", written "
              << t.written << ", malformed " << t.malformed << ", dropped " << t.dropped
              << ", lost " << t.lost << ", sequence gaps " << t.gaps << ", before match "
              << t.before_match << "\n";
    if (t.malformed > 0) {
      std::cerr << "    malformed payloads were rejected, not recorded (first: " << t.first_problem
                << ")\n";
    }
  }
  if (stats.dropped_queue_full > 0) {
    std::cerr << "  dropped (writer could not keep up): " << stats.dropped_queue_full << "\n";
  }
  if (stats.before_match > 0) {
    std::cerr << "  missed before the first match (written by a publisher before the recorder "
                 "matched it, from its sequence numbers; not in the file): "
              << stats.before_match << "\n";
  }
  if (stats.lost > 0) {
    std::cerr << "  lost (received, not in the file because writing failed): " << stats.lost
              << "\n";
  }
  if (!stats.error.empty()) {
    throw Error(stats.error);
  }
}

void run_replay(const ReplayArgs& a) {
  record::ReplayOptions o;
  o.input = a.file;
  o.domain = a.domain;
  o.participant_profile = a.profile;
  o.wait_for_subscribers_s = a.wait_s;
  o.schedule.rate = a.rate;
  if (a.start_s >= 0.0) {
    o.schedule.start_s = a.start_s;
  }
  if (a.end_s >= 0.0) {
    o.schedule.end_s = a.end_s;
  }
  o.schedule.topics = std::set<std::string>(a.topics.begin(), a.topics.end());
  o.schedule.loop = a.loop;
  o.schedule.as_fast_as_possible = a.afap;
  install_stop_handlers();
  o.schedule.should_stop = [] { return stop_requested(); };
  record::ReplayStats stats;
  try {
    stats = record::replay(o);
  } catch (const record::ReadError& e) {
    throw Error(e.what());
  } catch (const dds::DdsError& e) {
    throw Error(e.what());
  }
  const auto& s = stats.schedule;
  std::cerr << "poise replay: published " << s.delivered << " messages (" << s.passes
            << " passes) in " << s.elapsed_s << " s; recorded span " << s.recorded_span_s
            << " s; worst lateness " << s.max_late_s * 1e3 << " ms\n";
  for (const auto& [topic, n] : s.per_topic) {
    std::cerr << "  " << topic << ": " << n << "\n";
  }
  if (stats.write_failures > 0) {
    std::cerr << "  DDS refused " << stats.write_failures << " samples\n";
  }
  if (stats.malformed > 0) {
    std::cerr << "  skipped " << stats.malformed << " malformed payload(s) (not published)\n";
  }
  if (stats.channels_over_limit > 0) {
    std::cerr << "  skipped " << stats.over_limit_messages << " message(s) on " << stats.channels_over_limit
              << " channel(s) beyond the first " << stats.writers << " topics with messages (one DDS writer each)\n";
  }
  if (stats.damaged()) {
    std::cerr << "poise replay: the file is damaged ("
              << stats.corrupt_in_file + stats.schedule.problems.size()
              << " corrupt part(s) skipped, see above); the readable part was replayed\n";
  } else if (!stats.complete) {
    std::cerr << "poise replay: the file was incomplete (see above); the recovered part was "
                 "replayed\n";
  }
  refuse_damaged("replay", stats.damaged() || !stats.complete, a.allow_damaged);
}

}  // namespace

// not split: the options and help of `info`, `record`, `replay` and `process` in the order --help
// prints them.
void add_record_commands(CLI::App& app) {
  auto info_args = std::make_shared<InfoArgs>();
  CLI::App* info = app.add_subcommand(
      "info", "Describe an MCAP recording: topics, types, counts, rates, duration, and whether "
              "it is complete. Exit code 3 when the file is incomplete or damaged (the readable "
              "part is described).");
  info->add_option("file", info_args->file, "MCAP file")->required()->check(CLI::ExistingFile);
  info->add_flag("--verify", info_args->verify,
                 "read every chunk and check every CRC even if the summary is valid");
  info->callback([info_args] { run_info(*info_args); });

  auto rec = std::make_shared<RecordArgs>();
  CLI::App* record_cmd = app.add_subcommand(
      "record", "Record DDS topics to MCAP (payloads verbatim, omgidl schemas, QoS metadata).");
  add_output_file_option(record_cmd, &rec->output, "the recording, FILE.mcap", true);
  record_cmd->add_option("topics", rec->topics, "Topics to record (TOPIC...)");
  record_cmd->add_flag("--all", rec->all, "record every topic of a poise type");
  record_cmd->add_option("--duration", rec->duration_s, "stop after S seconds (0: Ctrl-C)")
      ->check(CLI::NonNegativeNumber);
  record_cmd->add_option("--split-size", rec->split_mb,
                         "start a new file (FILE_000.mcap, FILE_001.mcap, ...) past MB megabytes")
      ->check(CLI::NonNegativeNumber);
  record_cmd->add_option("--compression", rec->compression, "chunk compression")
      ->check(CLI::IsMember({"none", "zstd"}))
      ->capture_default_str();
  add_dds_profile_option(record_cmd, &rec->profile);
  add_deprecated_alias(record_cmd, "--profile", "--dds-profile", &rec->profile);
  add_domain_option(record_cmd, &rec->domain);
  record_cmd->callback([rec] {
    if (!rec->all && rec->topics.empty()) {
      throw CLI::ValidationError("topics", "name the topics to record, or use --all");
    }
    run_record(*rec);
  });

  auto rep = std::make_shared<ReplayArgs>();
  CLI::App* replay_cmd = app.add_subcommand(
      "replay", "Republish an MCAP recording over DDS, byte for byte, with recorded timing.");
  replay_cmd->add_option("file", rep->file, "MCAP file")->required()->check(CLI::ExistingFile);
  replay_cmd->add_option("topics", rep->topics, "Only these topics (TOPIC...; default: all)");
  replay_cmd->add_option("--speed", rep->rate, "Speed factor: play this many times faster than recorded (2 = twice as fast)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  add_deprecated_alias(replay_cmd, "--rate", "--speed", &rep->rate);
  replay_cmd->add_option("--start", rep->start_s, "start S seconds into the recording")
      ->check(CLI::NonNegativeNumber);
  replay_cmd->add_option("--end", rep->end_s, "stop S seconds into the recording")
      ->check(CLI::NonNegativeNumber);
  add_deprecated_alias(replay_cmd, "--topics", "TOPIC... after the file", &rep->topics);
  replay_cmd->add_flag("--loop", rep->loop, "start again at the end (Ctrl-C to stop)");
  replay_cmd->add_flag("--as-fast-as-possible", rep->afap, "ignore the recorded timing");
  replay_cmd->add_option("--wait", rep->wait_s,
                         "wait up to S seconds for subscribers before publishing")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  add_dds_profile_option(replay_cmd, &rep->profile);
  add_deprecated_alias(replay_cmd, "--profile", "--dds-profile", &rep->profile);
  replay_cmd->add_flag("--allow-damaged", rep->allow_damaged,
                       "exit 0 although the file is incomplete or has unreadable chunks (the "
                       "readable part is replayed either way; exit code 3 otherwise)");
  add_domain_option(replay_cmd, &rep->domain);
  replay_cmd->callback([rep] { run_replay(*rep); });

  auto proc = std::make_shared<ProcessArgs>();
  CLI::App* process_cmd = app.add_subcommand(
      "process", "Run a host's estimator components (or attitude filters) on a recording offline, "
                 "through the same step logic as the live nodes: no DDS, no sleeps, deterministic "
                 "(the same input gives a byte-identical output). The output holds the input "
                 "messages plus processed/<topic> for every topic the components publish live; "
                 "then a comparison with the recorded live estimates and truth/* is printed.");
  process_cmd->add_option("file", proc->file, "input MCAP file")->required()->check(CLI::ExistingFile);
  add_output_file_option(process_cmd, &proc->output, "the processed MCAP recording", true);
  process_cmd->add_option("--host", proc->host,
                          "host file: every estimator component runs with its parameters, on the "
                          "recorded inputs it subscribes to live (imu, vision_pose, vehicle_input; "
                          "the host's topic names)")
      ->check(CLI::ExistingFile);
  process_cmd->add_option("--set", proc->sets,
                          "NAME.KEY=VALUE: change a parameter of the host's component NAME (as in "
                          "its params map; VALUE is YAML, e.g. imu_delay_s=0.01, "
                          "q_body_camera=[1,0,0,0], filter_file=other.yaml); for a --filter NAME, and "
                          "KEY=VALUE without NAME for every --filter filter, the IMU it follows "
                          "(imu_sensor_id=ID; default: the first sensor heard) and the north keys "
                          "(declination_deg=D, location={lat_deg: .., lon_deg: ..}, date=...): "
                          "output in true ENU, frame id enu_true; repeatable")
      ->allow_extra_args(false)
      ->type_name("[NAME.]KEY=VALUE");
  process_cmd->add_option("--filter", proc->filters,
                          "NAME[=CONFIG.yaml]: an attitude filter to run alone (repeatable); see "
                          "`poise bench filters --help` for names");
  process_cmd->add_option("--imu-topic", proc->imu_topic, "IMU topic (default: host file / imu)");
  process_cmd->add_option("--order", proc->order,
                          "input order: stamp (sample stamps; vision at its capture stamp) or "
                          "recorded (the order the recorder received them)")
      ->check(CLI::IsMember({"stamp", "recorded"}))
      ->capture_default_str();
  process_cmd->add_option("--start", proc->start_s,
                          "process from S seconds into the recording (log time): what was logged "
                          "before is neither run nor copied, as if the recording began there (a "
                          "cold start mid-run)")
      ->check(CLI::Range(0.0, 1e9));
  process_cmd->add_option("--end", proc->end_s, "stop S seconds into the recording (log time)")
      ->check(CLI::Range(0.0, 1e9));
  process_cmd->add_option("--window", proc->window,
                          "FROM,TO: also score each processed attitude against truth between FROM and TO "
                          "seconds after its first estimate (RMSE, heading RMSE, NEES), e.g. the heading once "
                          "a disturbance has left a cold start")
      ->delimiter(',')
      ->expected(2)
      ->check(CLI::Range(0.0, 1e9));
  process_cmd->add_flag("!--no-compare", proc->compare, "do not print the comparison");
  process_cmd->add_flag("--allow-damaged", proc->allow_damaged,
                        "exit 0 although the input is incomplete or has unreadable chunks (the "
                        "readable part is processed either way; exit code 3 otherwise)");
  process_cmd->callback([proc] { run_process(*proc); });
}

}  // namespace poise::cli
