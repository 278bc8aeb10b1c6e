#include "poise/eval/runner.h"

#include "poise/core/attitude.h"

#include <cstdio>
#include <fstream>
#include <cmath>
#include <iomanip>
#include <ostream>
#include <sstream>
#include <stdexcept>

namespace poise::eval {

namespace {

// The one loop over a trial; covariances kept when `cov` is given, samples with an estimate
// counted in `estimated` when given.
std::vector<Eigen::Quaterniond> run(AttitudeFilter& filter, const BroadTrial& trial, std::vector<Eigen::Matrix3d>* cov,
                                    size_t* estimated) {
  filter.reset();
  if (auto* inputs = dynamic_cast<TrialInputs*>(&filter)) {
    inputs->begin_trial(trial);
  }
  std::vector<Eigen::Quaterniond> out;
  out.reserve(trial.size());
  if (cov != nullptr) {
    cov->reserve(trial.size());
  }
  size_t n_estimated = 0;
  for (size_t k = 0; k < trial.size(); ++k) {
    filter.update(trial.sample(k));
    const bool ready = filter.initialized();
    n_estimated += ready ? 1 : 0;
    out.push_back(ready ? filter.q_world_body() : Eigen::Quaterniond::Identity());
    if (cov != nullptr) {
      const std::optional<Eigen::Matrix3d> p = ready ? filter.attitude_covariance() : std::nullopt;
      cov->push_back(p ? *p : Eigen::Matrix3d::Constant(std::nan("")));
    }
  }
  if (estimated != nullptr) {
    *estimated = n_estimated;
  }
  return out;
}

}  // namespace

std::vector<Eigen::Quaterniond> run_filter(AttitudeFilter& filter, const BroadTrial& trial, size_t* estimated) {
  return run(filter, trial, nullptr, estimated);
}

TrialEstimates run_filter_estimates(AttitudeFilter& filter, const BroadTrial& trial, size_t* estimated) {
  TrialEstimates e;
  e.q = run(filter, trial, &e.cov, estimated);
  return e;
}

void write_estimate_csv(const std::string& path, const TrialEstimates& e, double rate_hz) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) {
    throw std::runtime_error("cannot write '" + path + "' (does the output directory exist and is it writable?)");
  }
  std::fputs("t_s,qw,qx,qy,qz,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz\n", f);
  for (size_t k = 0; k < e.q.size(); ++k) {
    const Eigen::Quaterniond& q = e.q[k];
    const Eigen::Matrix3d& p = e.cov[k];
    std::fprintf(f, "%.6f,%.9f,%.9f,%.9f,%.9f,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e\n", static_cast<double>(k) / rate_hz,
                 q.w(), q.x(), q.y(), q.z(), p(0, 0), p(0, 1), p(0, 2), p(1, 1), p(1, 2), p(2, 2));
  }
  if (std::fclose(f) != 0) {
    throw std::runtime_error("error while writing '" + path + "'");
  }
}

NeesSummary broad_consistency(const TrialEstimates& e, const BroadTrial& trial) {
  if (e.q.size() != trial.size() || e.cov.size() != trial.size()) {
    throw std::invalid_argument("broad_consistency: one estimate and covariance per sample is required");
  }
  NeesSummary s;
  for (size_t k = 0; k < trial.size(); ++k) {
    if (trial.movement[k] == 0 || !trial.opt_quat_wxyz[k].allFinite()) {
      continue;
    }
    const double norm = e.q[k].coeffs().norm();
    s.add(std::isfinite(norm) && norm > 0.0
              ? attitude_nees(world_attitude_error(e.q[k], quat_from_wxyz(trial.opt_quat_wxyz[k])), e.cov[k])
              : std::nan(""));
  }
  return s;
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

std::string format_consistency(const NeesSummary& nees) {
  std::ostringstream os;
  os << std::right;
  if (nees.samples() == 0) {
    os << std::setw(10) << "-" << std::setw(8) << "-";
    return os.str();
  }
  const double med = nees.median();
  os << std::setw(10);
  if (med < 1e4) {
    os << std::fixed << std::setprecision(2) << med;
  } else {
    os << std::scientific << std::setprecision(2) << med;
  }
  os << std::setw(8) << std::fixed << std::setprecision(1) << 100.0 * nees.fraction_inside(kNees95Dof3);
  return os.str();
}

void print_table(std::ostream& os, const std::string& filter_name, const std::vector<TrialResult>& results) {
  os << "BROAD RMSE (deg), filter " << filter_name << "\n";
  os << std::left << std::setw(48) << "trial" << std::right << std::setw(9) << "total" << std::setw(9)
     << "heading" << std::setw(9) << "incl" << std::setw(10) << "scored" << std::setw(10) << "NEES med" << std::setw(8)
     << "in95 %" << "\n";
  os << std::fixed << std::setprecision(3);
  for (const auto& r : results) {
    os << std::left << std::setw(48) << r.stem << format_trial_figure(r.errors, r.errors.total_deg, 9)
       << format_trial_figure(r.errors, r.errors.heading_deg, 9)
       << format_trial_figure(r.errors, r.errors.inclination_deg, 9) << std::right << std::setw(10)
       << r.errors.samples << format_consistency(r.nees);
    if (!r.errors.scored()) {
      os << "  no scorable samples (movement with a valid reference): excluded from the means";
    }
    if (r.errors.nonfinite_estimates > 0) {
      os << "  " << r.errors.nonfinite_estimates << " non-finite estimate(s) scored as 180 deg";
    }
    os << "\n";
  }
  const GroupMeans g = group_means(results);
  NeesSummary pooled_undisturbed;
  NeesSummary pooled_disturbed;
  NeesSummary pooled_all;
  for (const auto& r : results) {
    if (r.errors.scored()) {
      (r.disturbed ? pooled_disturbed : pooled_undisturbed).merge(r.nees);
      pooled_all.merge(r.nees);
    }
  }
  auto line = [&](const std::string& label, const TrialErrors& e, int n, const NeesSummary& nees) {
    os << std::left << std::setw(48) << (label + " (" + std::to_string(n) + " trials)")
       << format_mean_figure(e.total_deg, n, 9) << format_mean_figure(e.heading_deg, n, 9)
       << format_mean_figure(e.inclination_deg, n, 9) << std::setw(10) << "" << format_consistency(nees)
       << (n == 0 ? "  no trial: no figure" : "") << "\n";
  };
  line("mean undisturbed 01-23", g.undisturbed, g.n_undisturbed, pooled_undisturbed);
  line("mean disturbed 24-39", g.disturbed, g.n_disturbed, pooled_disturbed);
  line("mean all", g.all, g.n_undisturbed + g.n_disturbed, pooled_all);
  os << "scored: the samples the RMSE is over (movement and a valid reference quaternion); the sample\n"
        "count on stderr is every sample of the file. NEES med / in95 %: median NEES of the published\n"
        "covariance and % of scored samples with NEES <= 7.815 (consistent: about 2.37 and 95 %), per\n"
        "trial and over the pooled samples of each group; - without a covariance\n";
  if (!g.unscored.empty()) {
    os << "excluded from the means: " << g.unscored.size() << " trial(s) without scorable samples:";
    for (const auto& stem : g.unscored) {
      os << " " << stem;
    }
    os << "\n";
  }
}

}  // namespace poise::eval
