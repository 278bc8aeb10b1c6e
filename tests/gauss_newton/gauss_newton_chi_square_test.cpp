// Gauss-Newton's published covariance against the strict chi-square bounds (issue 31): a simulated
// sensor at rest with known white noise, M independent runs (seeds), the NEES averaged over the
// runs at each evaluated instant against the two-sided 95 % bounds for 3 M degrees of freedom
// divided by M (poise/testing/chi_square.h). Oracle: the simulator's truth.
#include "poise/core/attitude.h"
#include "poise/core/consistency.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/sim/sensor_simulator.h"
#include "poise/testing/chi_square.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <vector>

namespace poise {
namespace {

constexpr int kRuns = 50;                 // independent seeds
constexpr double kFirstS = 2.0;           // evaluated instants: from (the residual's 0.5 s average settled), s
constexpr double kLastS = 12.0;           // ... to (the scenario's first magnet comes at 15 s), s
constexpr double kEveryS = 0.5;           // ... every, s
// Each instant's average lies outside its 95 % bounds with probability 5 %; of 21 instants at most
// 3 may (P(more than 3 | consistent) = 1.6 %, binomial).
constexpr int kMaxOutside = 3;

TEST(GaussNewtonChiSquare, GivenASensorAtRestWithKnownNoiseWhenRunManyTimesThenTheAveragedNeesLiesInsideTheChiSquareBounds) {
  // GIVEN the simulator's static scenario (white noise, the Earth's field known to the solver)
  const int instants = static_cast<int>((kLastS - kFirstS) / kEveryS + 0.5) + 1;
  std::vector<double> sum(static_cast<size_t>(instants), 0.0);
  for (int run = 0; run < kRuns; ++run) {
    sim::SimConfig cfg = sim::make_scenario("static_magnet", 200.0, 1000 + static_cast<uint64_t>(run));
    GaussNewtonParams p;
    p.dip_deg = cfg.field.dip_deg;
    p.field_magnitude_ut = cfg.field.magnitude_ut;
    GaussNewton gn(p);
    sim::SensorSimulator simu(cfg);
    int next = 0;
    // WHEN it solves every sample
    while (!simu.done() && next < instants) {
      const sim::SimSample s = simu.next();
      const bool ok = gn.update(s.imu);
      if (ok && s.truth.t_s >= kFirstS + next * kEveryS) {
        const Eigen::Vector3d e = world_attitude_error(gn.result().q_world_body, s.truth.q_world_body);
        sum[static_cast<size_t>(next)] += attitude_nees(e, gn.attitude_covariance());
        ++next;
      }
    }
    ASSERT_EQ(next, instants) << "run " << run;
  }
  // THEN the NEES averaged over the runs lies inside the bounds at all but a few instants
  const testing::AveragedNeesBounds b = testing::averaged_nees_bounds_95(3, kRuns);
  int outside = 0;
  double mean = 0.0;
  for (int i = 0; i < instants; ++i) {
    const double avg = sum[static_cast<size_t>(i)] / kRuns;
    mean += avg / instants;
    outside += avg < b.lo || avg > b.hi ? 1 : 0;
  }
  std::printf("Gauss-Newton, %d runs: averaged NEES bounds [%.3f, %.3f], mean over %d instants %.3f, %d outside\n",
              kRuns, b.lo, b.hi, instants, mean, outside);
  EXPECT_LE(outside, kMaxOutside);
}

}  // namespace
}  // namespace poise
