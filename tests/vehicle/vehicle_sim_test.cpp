// Paper 001's qualitative results reproduced on the vehicle simulator (seeded, with margins).
#include "poise/eval/vehicle_eval.h"

#include "poise/core/attitude.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace poise {
namespace {

constexpr uint64_t kSeeds[] = {1, 2};
/// Switched must be at least this much better than TRIAD alone during lateral manoeuvres.
constexpr double kLateralBeatFactor = 0.5;
/// Steady state after the final stop (TRIAD on averaged static data), deg.
constexpr double kFinalStopTolDeg = 0.2;
/// Steady state at the end of straight driving on a flat road (EKF), deg.
constexpr double kDrivingEndTolDeg = 0.3;

VehicleScore run(const std::string& scenario, VehicleMode mode, uint64_t seed) {
  VehicleSimConfig sim;
  sim.scenario = scenario;
  sim.seed = seed;
  VehicleParams p;
  p.mode = mode;
  return score_vehicle(sim, p);
}

class VehicleLateral : public ::testing::TestWithParam<const char*> {};

TEST_P(VehicleLateral, GivenLateralManoeuvresThenSwitchedBeatsTriad) {
  // Paper 001 section 4: TRIAD alone degrades whenever a_y carries inertial force (the virtual
  // gravity (7) is wrong in a turn); the switched estimator runs the EKF there.
  for (uint64_t seed : kSeeds) {
    const VehicleScore triad = run(GetParam(), VehicleMode::kTriad, seed);
    const VehicleScore sw = run(GetParam(), VehicleMode::kSwitched, seed);
    ASSERT_GT(sw.lateral_samples, 100U);
    EXPECT_LT(sw.rmse_lateral.roll_deg, kLateralBeatFactor * triad.rmse_lateral.roll_deg) << seed;
    EXPECT_LT(sw.rmse_lateral.pitch_deg, kLateralBeatFactor * triad.rmse_lateral.pitch_deg) << seed;
    EXPECT_LT(sw.rmse_lateral.yaw_deg, kLateralBeatFactor * triad.rmse_lateral.yaw_deg) << seed;
    EXPECT_EQ(sw.rejects.total(), 0U);
  }
}

INSTANTIATE_TEST_SUITE_P(Cases, VehicleLateral, ::testing::Values("double_lane_change", "mountain_road"));

class VehicleSteadyState : public ::testing::TestWithParam<const char*> {};

TEST_P(VehicleSteadyState, GivenTheFinalStopThenSwitchedErrorConverges) {
  for (uint64_t seed : kSeeds) {
    const VehicleScore sw = run(GetParam(), VehicleMode::kSwitched, seed);
    EXPECT_LT(sw.final_abs_error.roll_deg, kFinalStopTolDeg) << seed;
    EXPECT_LT(sw.final_abs_error.pitch_deg, kFinalStopTolDeg) << seed;
    EXPECT_LT(sw.final_abs_error.yaw_deg, kFinalStopTolDeg) << seed;
    EXPECT_GT(sw.triad_fraction, 0.05);
    EXPECT_LT(sw.triad_fraction, 0.5);
  }
}

INSTANTIATE_TEST_SUITE_P(AllCases, VehicleSteadyState,
                         ::testing::Values("double_lane_change", "bank_20deg", "hill", "mountain_road"));

TEST(VehicleSim, GivenFlatRoadWhenDrivingStraightAfterTheManoeuvreThenEkfErrorIsSmall) {
  for (uint64_t seed : kSeeds) {
    const VehicleScore sw = run("double_lane_change", VehicleMode::kSwitched, seed);
    EXPECT_LT(sw.driving_end_abs_error.roll_deg, kDrivingEndTolDeg);
    EXPECT_LT(sw.driving_end_abs_error.pitch_deg, kDrivingEndTolDeg);
    EXPECT_LT(sw.driving_end_abs_error.yaw_deg, kDrivingEndTolDeg);
  }
}

TEST(VehicleSim, GivenA20DegBankWhenDrivingThenTheModelUnderestimatesTheBank) {
  // Paper 001 conclusion: the spring-damper treats the bank as suspension deflection and its
  // restoring force outweighs the magnetometer: the bank is estimated smaller than it is. TRIAD
  // (no lateral manoeuvre) is right, and the switched estimator recovers when the vehicle stops.
  constexpr double kUnderestimateMinDeg = 5.0;
  constexpr double kTriadOnBankTolDeg = 1.0;
  const VehicleScore ekf = run("bank_20deg", VehicleMode::kEkf, 1);
  const VehicleScore triad = run("bank_20deg", VehicleMode::kTriad, 1);
  const VehicleScore sw = run("bank_20deg", VehicleMode::kSwitched, 1);
  ASSERT_GT(ekf.bank_samples, 500U);
  EXPECT_LT(ekf.mean_roll_error_on_bank_deg, -kUnderestimateMinDeg);
  EXPECT_LT(std::abs(triad.mean_roll_error_on_bank_deg), kTriadOnBankTolDeg);
  EXPECT_LT(sw.final_abs_error.roll_deg, kFinalStopTolDeg);
  EXPECT_GT(ekf.final_abs_error.roll_deg, kUnderestimateMinDeg);  // EKF alone never recovers
}

TEST(VehicleSim, NoiselessStandstillOnTheBankGivesExactTriad) {
  VehicleSimConfig sim;
  sim.scenario = "bank_20deg";
  sim.accel_noise_mps2 = 0.0;
  sim.yaw_rate_noise_rps = 0.0;
  sim.yaw_rate_bias_max_rps = 0.0;
  sim.mag_noise_ut = 0.0;
  sim.speed_noise_mps = 0.0;
  const auto samples = simulate_vehicle(sim);
  ASSERT_TRUE(samples.back().true_static);
  EXPECT_NEAR(samples.back().road_bank_rad, 20.0 * kRadPerDeg, 1e-9);
  // The body leans further downhill on its suspension (phi_v > 0 when the left side is up).
  EXPECT_GT(samples.back().true_roll_rad, samples.back().road_bank_rad);
  // Per-sample TRIAD (no averaging, which would keep a trace of the body's settling after the stop).
  VehicleParams p;
  p.static_average = false;
  const VehicleScore s = score_vehicle(sim, p);
  EXPECT_LT(s.final_abs_error.roll_deg, 1e-3);
  EXPECT_LT(s.final_abs_error.yaw_deg, 1e-3);
}

TEST(VehicleSim, SeededAndUnknownCaseRejected) {
  VehicleSimConfig a;
  a.seed = 5;
  const auto ra = simulate_vehicle(a);
  const auto rb = simulate_vehicle(a);
  ASSERT_EQ(ra.size(), rb.size());
  for (std::size_t k = 0; k < ra.size(); k += 97) {
    ASSERT_EQ(ra[k].input.mag_ut, rb[k].input.mag_ut);
  }
  VehicleSimConfig bad;
  bad.scenario = "moon";
  EXPECT_THROW(simulate_vehicle(bad), std::invalid_argument);
}

}  // namespace
}  // namespace poise
