// True north for the evaluation tools (`eval broad`, `tune`, `bench filters`, `process --filter`):
// `--set KEY=VALUE` with the host files' north keys. Oracle: the conventions' q_true_body =
// Rz(-D) q_magnetic_body (docs/CONVENTIONS.md) applied to the same filter without a declination.
#include "poise/core/attitude.h"
#include "poise/eval/filter_registry.h"
#include "poise/eval/north_filter.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/selective_ekf/selective_ekf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>

namespace poise::eval {
namespace {

constexpr double kTurnTolRad = 1e-12;  // one rotation about z of a unit quaternion

std::string error_of(const std::vector<std::string>& sets) {
  try {
    north_from_sets(sets, "2026-11-24");
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(NorthFromSets, GivenADeclinationOrALocationThenTheOutputIsTrueEnuAndAnythingElseIsRefused) {
  EXPECT_FALSE(north_from_sets({}, "2026-11-24").true_north) << "no --set: magnetic ENU";
  const NorthReference d = north_from_sets({"declination_deg=10"}, "2026-11-24");
  EXPECT_TRUE(d.true_north);
  EXPECT_STREQ(d.frame_id(), "enu_true");
  EXPECT_NEAR(d.declination_rad, 10.0 * kRadPerDeg, 1e-15);
  // a location: the model's declination (WMM2025 near Munich: a few deg east)
  const NorthReference loc = north_from_sets({"location={lat_deg: 48.14, lon_deg: 11.58}", "date=2026-11-24"}, "x");
  EXPECT_TRUE(loc.true_north);
  EXPECT_GT(loc.declination_rad, 2.0 * kRadPerDeg);
  EXPECT_LT(loc.declination_rad, 6.0 * kRadPerDeg);
  EXPECT_NE(error_of({"sigma_mag_ut=1"}).find("unknown key 'sigma_mag_ut' (known: declination_deg"), std::string::npos);
  EXPECT_NE(error_of({"declination_deg"}).find("expected KEY=VALUE"), std::string::npos);
  EXPECT_NE(error_of({"declination_deg=east"}).find("declination_deg must be a number"), std::string::npos);
  EXPECT_NE(error_of({"declination_deg=1", "declination_deg=2"}).find("given twice"), std::string::npos);
  EXPECT_NE(error_of({"declination_deg=1", "location={lat_deg: 1, lon_deg: 2}"}).find("not both"), std::string::npos);
  EXPECT_NE(error_of({"date=2026-01-01"}).find("need a location"), std::string::npos);
}

TEST(NorthFromSets, GivenADeclinationThenTheWrappedFiltersHeadingIsTheMagneticOneMinusIt) {
  const NorthReference north = north_from_sets({"declination_deg=10"}, "2026-11-24");
  auto magnetic = make_filter("parallel_kf");
  auto truen = with_north(make_filter("parallel_kf"), north);
  ImuSample s;
  s.accel_mps2 = Eigen::Vector3d(0.0, 0.0, kStandardGravityMps2);
  s.mag_ut = Eigen::Vector3d(0.0, 20.0, -40.0);
  s.has_mag = true;
  for (int k = 0; k < 100; ++k) {
    s.stamp_ns = 1'000'000'000 + int64_t{k} * 10'000'000;
    s.gyro_rps = Eigen::Vector3d(0.0, 0.0, 0.3);
    ASSERT_TRUE(magnetic->update(s));
    ASSERT_TRUE(truen->update(s));
    const Eigen::Quaterniond want =
        Eigen::Quaterniond(Eigen::AngleAxisd(-10.0 * kRadPerDeg, Eigen::Vector3d::UnitZ())) * magnetic->q_world_body();
    ASSERT_LT(quat_angle_between(truen->q_world_body(), want), kTurnTolRad) << k;
  }
  // without a declination the filter is returned as it is
  AttitudeFilter* raw = magnetic.get();
  EXPECT_EQ(with_north(std::move(magnetic), NorthReference{}).get(), raw);
}

/// Records what it is seeded with.
class SeedProbe : public AttitudeFilter {
 public:
  bool update(const ImuSample& /*s*/) override { return true; }
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override { return Eigen::Quaterniond::Identity(); }
  [[nodiscard]] bool initialized() const override { return true; }
  void reset() override {}
  void seed_field(double field_ut, double dip_deg) override {
    field = field_ut;
    dip = dip_deg;
  }
  double field = -1.0;
  double dip = -1.0;
};

TEST(NorthFromSets, GivenALocationThenTheModelsFieldSeedsTheFiltersFieldReferenceUnlessConfigured) {
  // Oracle: the model's |B| and dip as resolve_north gives them (checked against NOAA's test
  // values by the geomagnetic tests); a configured reference is the user's and stays.
  const NorthReference north = north_from_sets({"location={lat_deg: 48.14, lon_deg: 11.58}", "date=2026-11-24"}, "x");
  ASSERT_FALSE(std::isnan(north.field_ut));
  ASSERT_FALSE(std::isnan(north.dip_deg));
  auto probe = std::make_unique<SeedProbe>();
  SeedProbe* seen = probe.get();
  const auto wrapped = with_north(std::move(probe), north);
  EXPECT_EQ(seen->field, north.field_ut);
  EXPECT_EQ(seen->dip, north.dip_deg);

  ParallelKfFilter pkf;
  pkf.seed_field(north.field_ut, north.dip_deg);
  EXPECT_EQ(pkf.core().params().field_magnitude_ut, north.field_ut);
  EXPECT_EQ(pkf.core().params().dip_deg, north.dip_deg);
  ParallelKfParams configured;
  configured.field_magnitude_ut = 48.0;
  configured.dip_deg = 64.0;
  ParallelKfFilter kept(configured);
  kept.seed_field(north.field_ut, north.dip_deg);
  EXPECT_EQ(kept.core().params().field_magnitude_ut, 48.0);
  EXPECT_EQ(kept.core().params().dip_deg, 64.0);
  SelectiveEkfFilter sekf;
  sekf.seed_field(north.field_ut, north.dip_deg);
  EXPECT_EQ(sekf.core().params().field_magnitude_ut, north.field_ut);
  EXPECT_EQ(sekf.core().params().dip_deg, north.dip_deg);
  GaussNewtonFilter gn;
  gn.seed_field(north.field_ut, north.dip_deg);
  EXPECT_EQ(gn.core().params().dip_deg, north.dip_deg);
  // a declination alone carries no field: nothing changes
  ParallelKfFilter plain;
  plain.seed_field(std::nan(""), std::nan(""));
  EXPECT_TRUE(std::isnan(plain.core().params().field_magnitude_ut));
}

}  // namespace
}  // namespace poise::eval
