// Barometric height (paper 003 eqs. 6-7) against the ISA table and its own inverse.
#include "poise/altitude/altitude_filter.h"

#include <gtest/gtest.h>

#include <cmath>

namespace poise {
namespace {

constexpr double kIsaTableTolM = 0.5;      // ISA tables print pressure to 0.1 hPa ~ 1 m; we allow 0.5 m
constexpr double kRoundTripTolM = 1e-6;    // numerical round trip
constexpr double kP0 = IsaConstants::kP0Pa;

TEST(BaroHeight, StandardPressureIsZeroHeight) {
  EXPECT_NEAR(baro_height_m(kP0, kP0), 0.0, 1e-12);
}

TEST(BaroHeight, MatchesIsaTableAt1000And3000m) {
  // ISA: 1000 m -> 898.746 hPa, 3000 m -> 701.085 hPa (US Standard Atmosphere 1976).
  EXPECT_NEAR(baro_height_m(89874.6, kP0), 1000.0, kIsaTableTolM);
  EXPECT_NEAR(baro_height_m(70108.5, kP0), 3000.0, kIsaTableTolM);
}

TEST(BaroHeight, InverseRoundTrip) {
  for (double h : {-300.0, 0.0, 12.5, 850.0, 4000.0}) {
    EXPECT_NEAR(baro_height_m(isa_pressure_pa(h, kP0), kP0), h, kRoundTripTolM) << h;
  }
}

TEST(BaroHeight, ReferencePressureShiftsTheZero) {
  // GIVEN a QNH of 1020 hPa WHEN the sensor reads 1013.25 hPa THEN it is ~56 m above the QNH level.
  const double h = baro_height_m(kP0, 102000.0);
  EXPECT_NEAR(h, baro_height_m(kP0, 102000.0, false), 1e-12);
  EXPECT_GT(h, 55.0);
  EXPECT_LT(h, 58.0);
  EXPECT_NEAR(baro_height_m(102000.0, 102000.0), 0.0, 1e-12);
}

TEST(BaroHeight, PaperRoundedConstantsDifferSlightly) {
  // 44300 / 0.19 vs 44330.8 / 0.19026: about 0.2 % at 1000 m.
  const double exact = baro_height_m(89876.0, kP0, false);
  const double rounded = baro_height_m(89876.0, kP0, true);
  EXPECT_NE(exact, rounded);
  EXPECT_NEAR(rounded, exact, 0.005 * exact);
}

TEST(BaroHeight, NonPositiveOrNanPressureIsNan) {
  EXPECT_TRUE(std::isnan(baro_height_m(0.0, kP0)));
  EXPECT_TRUE(std::isnan(baro_height_m(-5.0, kP0)));
  EXPECT_TRUE(std::isnan(baro_height_m(std::nan(""), kP0)));
}

}  // namespace
}  // namespace poise
