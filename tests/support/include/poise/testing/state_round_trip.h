// For the estimator cores' state tests: state() / set_state() / reset() round-trip exactly.
// A `Fingerprint` writes everything a filter reports after a sample in hexadecimal floating point
// (so two runs compare bit for bit, NaN included); expect_state_round_trips() runs samples, then
// runs them again from the saved state (in a new filter and in the same one) and after reset().
// Header-only; the test links the core (and so poise_core).
#pragma once

#include "poise/core/sample_check.h"
#include "poise/core/source_report.h"

#include <Eigen/Core>
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace poise::testing {

/// Everything a filter reports, as text that is equal exactly when the values are bit-identical.
class Fingerprint {
 public:
  Fingerprint& add(double v) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%a ", v);
    text_ += buf;
    return *this;
  }
  Fingerprint& add(bool v) { return add(v ? 1.0 : 0.0); }
  Fingerprint& add(int64_t v) {
    text_ += std::to_string(v) + " ";
    return *this;
  }
  Fingerprint& add(uint64_t v) {
    text_ += std::to_string(v) + " ";
    return *this;
  }
  template <typename Derived>
  Fingerprint& add(const Eigen::DenseBase<Derived>& m) {
    for (Eigen::Index r = 0; r < m.rows(); ++r) {
      for (Eigen::Index c = 0; c < m.cols(); ++c) {
        add(static_cast<double>(m.derived().coeff(r, c)));
      }
    }
    text_ += "| ";
    return *this;
  }
  Fingerprint& add(const RejectCounters& counters) {
    for (const uint64_t n : counters.by_reason) {
      add(n);
    }
    return *this;
  }
  /// Every field of every report: decision, reason, innovation, variance, test ratio, last fused
  /// stamp and both counters.
  Fingerprint& add(const SourceReports& reports) {
    for (const SourceReport& r : reports) {
      text_ += std::to_string(static_cast<int>(r.decision)) + " " + std::string(r.reason) + " ";
      add(r.innovation).add(r.innovation_variance).add(r.test_ratio).add(r.last_fused_stamp_ns);
      add(r.fused_count).add(r.rejected_count);
      text_ += "; ";
    }
    return *this;
  }
  [[nodiscard]] const std::string& str() const { return text_; }

 private:
  std::string text_;
};

/// GIVEN `filter` after some samples: saves state() and runs `samples`, fingerprinting it with
/// `print(filter)` after each. Then, over the same samples, each of these must fingerprint the
/// same bit for bit: a new filter (`make()`, same parameters) given the saved state; `filter`
/// itself given the saved state back; and, after reset(), `filter` next to a new one.
template <typename Filter, typename Sample, typename Make, typename Print>
void expect_state_round_trips(Filter& filter, const std::vector<Sample>& samples, Make make, Print print) {
  const auto saved = filter.state();
  std::vector<std::string> first;
  first.reserve(samples.size());
  for (const Sample& s : samples) {
    filter.update(s);
    first.push_back(print(filter));
  }
  Filter other = make();
  other.set_state(saved);
  for (std::size_t k = 0; k < samples.size(); ++k) {
    other.update(samples[k]);
    ASSERT_EQ(print(other), first[k]) << "sample " << k << ": a new filter given the state";
  }
  filter.set_state(saved);
  for (std::size_t k = 0; k < samples.size(); ++k) {
    filter.update(samples[k]);
    ASSERT_EQ(print(filter), first[k]) << "sample " << k << ": the filter given its state back";
  }
  filter.reset();
  Filter fresh = make();
  ASSERT_EQ(print(filter), print(fresh)) << "right after reset()";
  for (std::size_t k = 0; k < samples.size(); ++k) {
    filter.update(samples[k]);
    fresh.update(samples[k]);
    ASSERT_EQ(print(filter), print(fresh)) << "sample " << k << " after reset(), next to a new filter";
  }
}

}  // namespace poise::testing
