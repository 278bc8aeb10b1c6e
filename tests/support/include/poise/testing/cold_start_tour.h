// For the cold-start tests of the attitude filters (issue 31 "cold start next to a magnet"): the
// simulator's tour (200 Hz, seed 1) and its times. The tour's first magnet, brought near
// (30, 10, -20) uT in the world on a 50 uT / 60 deg field, is at full strength 7 s in and has left
// 5 s later; the attached magnet starts at 22 s. Header-only; the test links poise_sim.
#pragma once

#include "poise/sim/sensor_simulator.h"

namespace poise::testing {

inline constexpr double kTourColdStartS = 7.0;       ///< a filter's first sample, inside the magnet, s
inline constexpr double kTourMagnetGoneS = 12.0;     ///< 5 s + 1.5 s ramp + 4 s + 1.5 s, s
inline constexpr double kTourSettleS = 2.0;          ///< "2 s after the magnet has left", s
inline constexpr double kTourAttachedMagnetS = 22.0; ///< the attached magnet starts, s

/// Calls `step(sample)` for every sample of the tour from `from_s` until the attached magnet.
template <typename Step>
void run_tour_until_attached_magnet(double from_s, Step&& step) {
  sim::SensorSimulator simu(sim::make_scenario("tour", 200.0, 1));
  while (!simu.done()) {
    const sim::SimSample s = simu.next();
    if (s.truth.t_s >= kTourAttachedMagnetS) {
      return;
    }
    if (s.truth.t_s >= from_s) {
      step(s);
    }
  }
}

}  // namespace poise::testing
