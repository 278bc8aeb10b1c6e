#include "poise/eval/runner.h"

#include <cstdio>
#include <fstream>
#include <cmath>
#include <iomanip>
#include <ostream>
#include <sstream>
#include <stdexcept>

namespace poise::eval {

std::vector<Eigen::Quaterniond> run_filter(AttitudeFilter& filter, const BroadTrial& trial, size_t* estimated) {
  filter.reset();
  if (auto* inputs = dynamic_cast<TrialInputs*>(&filter)) {
    inputs->begin_trial(trial);
  }
  std::vector<Eigen::Quaterniond> out;
  out.reserve(trial.size());
  size_t n_estimated = 0;
  for (size_t k = 0; k < trial.size(); ++k) {
    filter.update(trial.sample(k));
    const bool ready = filter.initialized();
    n_estimated += ready ? 1 : 0;
    out.push_back(ready ? filter.q_world_body() : Eigen::Quaterniond::Identity());
  }
  if (estimated != nullptr) {
    *estimated = n_estimated;
  }
  return out;
}

void write_quaternion_csv(const std::string& path, const std::vector<Eigen::Quaterniond>& q, double rate_hz) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) {
    throw std::runtime_error("cannot write '" + path + "' (does the output directory exist and is it writable?)");
  }
  std::fputs("t_s,qw,qx,qy,qz\n", f);
  for (size_t k = 0; k < q.size(); ++k) {
    std::fprintf(f, "%.6f,%.9f,%.9f,%.9f,%.9f\n", static_cast<double>(k) / rate_hz, q[k].w(), q[k].x(),
                 q[k].y(), q[k].z());
  }
  const bool failed = std::ferror(f) != 0;  // a write that failed before the last one
  if (std::fclose(f) != 0 || failed) {
    throw std::runtime_error("error while writing '" + path + "'");
  }
}

GroupMeans group_means(const std::vector<TrialResult>& results) {
  GroupMeans g;
  auto add = [](TrialErrors& acc, const TrialErrors& e) {
    acc.total_deg += e.total_deg;
    acc.heading_deg += e.heading_deg;
    acc.inclination_deg += e.inclination_deg;
    acc.samples += e.samples;
    acc.nonfinite_estimates += e.nonfinite_estimates;
  };
  for (const auto& r : results) {
    if (!r.errors.scored()) {  // no figure: excluded, never averaged in as 0
      g.unscored.push_back(r.stem);
      continue;
    }
    add(r.disturbed ? g.disturbed : g.undisturbed, r.errors);
    add(g.all, r.errors);
    (r.disturbed ? g.n_disturbed : g.n_undisturbed)++;
  }
  auto div = [](TrialErrors& e, int n) {
    if (n > 0) {
      e.total_deg /= n;
      e.heading_deg /= n;
      e.inclination_deg /= n;
    }
  };
  div(g.undisturbed, g.n_undisturbed);
  div(g.disturbed, g.n_disturbed);
  div(g.all, g.n_undisturbed + g.n_disturbed);
  return g;
}

std::string format_trial_figure(const TrialErrors& e, double value, int width) {
  std::ostringstream os;
  os << std::right << std::setw(width);
  if (e.scored()) {
    os << std::fixed << std::setprecision(3) << value;
  } else {
    os << "-";
  }
  return os.str();
}

std::string format_mean_figure(double value, int n, int width) {
  std::ostringstream os;
  os << std::right << std::setw(width);
  if (n > 0 && std::isfinite(value)) {
    os << std::fixed << std::setprecision(3) << value;
  } else {
    os << "-";
  }
  return os.str();
}

void print_table(std::ostream& os, const std::string& filter_name, const std::vector<TrialResult>& results) {
  os << "BROAD RMSE (deg), filter " << filter_name << "\n";
  os << std::left << std::setw(48) << "trial" << std::right << std::setw(9) << "total" << std::setw(9)
     << "heading" << std::setw(9) << "incl" << std::setw(10) << "scored" << "\n";
  os << std::fixed << std::setprecision(3);
  for (const auto& r : results) {
    os << std::left << std::setw(48) << r.stem << format_trial_figure(r.errors, r.errors.total_deg, 9)
       << format_trial_figure(r.errors, r.errors.heading_deg, 9)
       << format_trial_figure(r.errors, r.errors.inclination_deg, 9) << std::right << std::setw(10)
       << r.errors.samples;
    if (!r.errors.scored()) {
      os << "  no scorable samples (movement with a valid reference): excluded from the means";
    }
    if (r.errors.nonfinite_estimates > 0) {
      os << "  " << r.errors.nonfinite_estimates << " non-finite estimate(s) scored as 180 deg";
    }
    os << "\n";
  }
  const GroupMeans g = group_means(results);
  auto line = [&](const std::string& label, const TrialErrors& e, int n) {
    os << std::left << std::setw(48) << (label + " (" + std::to_string(n) + " trials)")
       << format_mean_figure(e.total_deg, n, 9) << format_mean_figure(e.heading_deg, n, 9)
       << format_mean_figure(e.inclination_deg, n, 9) << (n == 0 ? "  no trial: no figure" : "") << "\n";
  };
  line("mean undisturbed 01-23", g.undisturbed, g.n_undisturbed);
  line("mean disturbed 24-39", g.disturbed, g.n_disturbed);
  line("mean all", g.all, g.n_undisturbed + g.n_disturbed);
  os << "scored: the samples the RMSE is over (movement and a valid reference quaternion); the sample\n"
        "count on stderr is every sample of the file\n";
  if (!g.unscored.empty()) {
    os << "excluded from the means: " << g.unscored.size() << " trial(s) without scorable samples:";
    for (const auto& stem : g.unscored) {
      os << " " << stem;
    }
    os << "\n";
  }
}

}  // namespace poise::eval
