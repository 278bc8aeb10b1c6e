#include "poise/charts/plot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <utility>
#include <vector>
#include <unistd.h>

namespace poise::charts {
namespace {

TEST(NiceTicks, CoverTheRangeWithRoundSteps) {
  const auto t = nice_ticks(0.0, 10.0, 5);
  ASSERT_EQ(t.size(), 6U);
  EXPECT_DOUBLE_EQ(t.front(), 0.0);
  EXPECT_DOUBLE_EQ(t[1], 2.0);
  EXPECT_DOUBLE_EQ(t.back(), 10.0);
  const auto u = nice_ticks(-0.37, 0.41, 4);
  for (double v : u) {
    EXPECT_GE(v, -0.37);
    EXPECT_LE(v, 0.41);
  }
  EXPECT_TRUE(nice_ticks(1.0, 1.0).empty());
}

TEST(WritePng, WritesADecodablePngOfTheRequestedSize) {
  Figure f;
  f.title = "test";
  f.width_px = 800;
  f.panel_height_px = 200;
  Panel p;
  p.title = "sine";
  Series s;
  s.label = "sin";
  for (int i = 0; i < 1000; ++i) {
    s.x.push_back(i * 0.01);
    s.y.push_back(i == 500 ? std::nan("") : std::sin(i * 0.01));
  }
  p.series.push_back(s);
  p.bands.push_back({2.0, 4.0, "band", {255, 200, 120}});
  f.panels = {p, p};
  const std::string path = std::filesystem::temp_directory_path() / ("poise_plot_" + std::to_string(::getpid()) + ".png");
  write_png(f, path);
  FILE* file = std::fopen(path.c_str(), "rb");
  ASSERT_NE(file, nullptr);
  unsigned char header[24] = {};
  ASSERT_EQ(std::fread(header, 1, sizeof header, file), sizeof header);
  std::fclose(file);
  EXPECT_EQ(header[1], 'P');
  EXPECT_EQ(header[2], 'N');
  EXPECT_EQ(header[3], 'G');
  const unsigned width = (header[16] << 24) | (header[17] << 16) | (header[18] << 8) | header[19];
  const unsigned height = (header[20] << 24) | (header[21] << 16) | (header[22] << 8) | header[23];
  EXPECT_EQ(width, 800U);
  EXPECT_EQ(height, 50U + 2U * 200U);
  std::remove(path.c_str());
}

// GIVEN the episodes of the demo's tour (overlapping bands, one at the right edge) as start and
// label width in px WHEN their labels are placed THEN no two labels on a row overlap (nor come
// closer than the gap), each starts at its band unless it would run past the right edge (then it
// ends there), and the rows used are as few as the first-fit oracle worked out by hand.
TEST(BandLabels, GivenOverlappingEpisodesWhenPlacedThenNoTwoLabelsOverlapAndNoneRunsPastTheEdge) {
  constexpr int kRight = 1000;
  constexpr int kGap = 6;
  // magnet near @100 (90 wide), tag lost @150 (70), stairs up @300 (80), stairs down @420 (90),
  // magnet attached @430 (120), camera blackout @450 (160), no label @460, stairs up @960 (80)
  const std::vector<std::pair<int, int>> bands{{100, 90}, {150, 70}, {300, 80}, {420, 90},
                                               {430, 120}, {450, 160}, {460, 0}, {960, 80}};
  int rows = 0;
  const auto places = place_band_labels(bands, kRight, kGap, rows);
  ASSERT_EQ(places.size(), bands.size());
  // by hand: row 0: magnet near [100,190), stairs up [300,380), stairs down [420,510),
  //          stairs up shifted to [920,1000); row 1: tag lost [150,220), magnet attached
  //          [430,550); row 2: camera blackout [450,610)
  const std::vector<int> expected_rows{0, 1, 0, 0, 1, 2, -1, 0};
  for (std::size_t i = 0; i < bands.size(); ++i) {
    EXPECT_EQ(places[i].row, expected_rows[i]) << i;
  }
  EXPECT_EQ(rows, 3);
  EXPECT_EQ(places[7].x_px, kRight - 80) << "shifted left to end at the edge";
  EXPECT_EQ(places[0].x_px, 100) << "otherwise at the band's start";
  for (std::size_t i = 0; i < bands.size(); ++i) {
    for (std::size_t j = i + 1; j < bands.size(); ++j) {
      if (places[i].row < 0 || places[i].row != places[j].row) {
        continue;
      }
      const int a0 = places[i].x_px;
      const int a1 = a0 + bands[i].second;
      const int b0 = places[j].x_px;
      const int b1 = b0 + bands[j].second;
      EXPECT_TRUE(a1 + kGap <= b0 || b1 + kGap <= a0) << i << " and " << j << " overlap on row " << places[i].row;
    }
    if (places[i].row >= 0) {
      EXPECT_LE(places[i].x_px + bands[i].second, kRight) << i;
    }
  }
}

TEST(WritePng, UnwritablePathThrows) {
  Figure f;
  f.panels.push_back(Panel{});
  EXPECT_THROW(write_png(f, "/nonexistent/dir/x.png"), std::runtime_error);
}

}  // namespace
}  // namespace poise::charts
