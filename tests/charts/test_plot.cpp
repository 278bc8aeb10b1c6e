#include "poise/charts/plot.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
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

TEST(WritePng, UnwritablePathThrows) {
  Figure f;
  f.panels.push_back(Panel{});
  EXPECT_THROW(write_png(f, "/nonexistent/dir/x.png"), std::runtime_error);
}

}  // namespace
}  // namespace poise::charts
