// Issue 19 oracle for the estimator cores: one hostile sample among valid ones. The hostile core
// gets samples 0..n-1 with a spoilt copy of sample at-1 (stamped half a step later) inserted
// before sample `at`; the clean core never sees it, or, when only a part of the sample is refused
// (a pressure, a magnetometer), sees the same sample without that part. Callers then compare the
// counters and the outputs of the two.
#pragma once

#include <cstdint>

namespace poise::testing {

/// `sample(k)`: valid sample k; `spoil(s)`: makes `s` hostile; `drop_refused(s)`: removes the part
/// a partly refused sample loses (used when !whole_sample). Returns update()'s result for the
/// hostile sample.
template <class Core, class SampleAt, class Spoil, class DropRefused>
bool run_with_one_hostile_sample(Core& hostile, Core& clean, int n, int at, int64_t half_step_ns,
                                 bool whole_sample, SampleAt sample, Spoil spoil, DropRefused drop_refused) {
  bool used = false;
  for (int k = 0; k < n; ++k) {
    if (k == at) {
      auto h = sample(at - 1);
      h.stamp_ns += half_step_ns;
      auto partial = h;
      spoil(h);
      used = hostile.update(h);
      if (!whole_sample) {
        drop_refused(partial);
        clean.update(partial);
      }
    }
    hostile.update(sample(k));
    clean.update(sample(k));
  }
  return used;
}

}  // namespace poise::testing
