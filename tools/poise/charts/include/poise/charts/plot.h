// Line charts written as PNG (drawn with OpenCV), for reports a person looks at: `poise demo`
// writes estimate-vs-truth, disturbance and altitude charts with them.
#pragma once

#include <array>
#include <string>
#include <utility>
#include <vector>

namespace poise::charts {

/// One line of a chart.
struct Series {
  std::string label;  ///< in the legend; empty: not in it
  std::vector<double> x;
  std::vector<double> y;
  std::array<int, 3> rgb{31, 119, 180};
  int thickness = 2;
  bool dashed = false;
};

/// A shaded band on the x axis (e.g. "magnet near", "tag lost").
struct Band {
  double x0 = 0.0;
  double x1 = 0.0;
  std::string label;
  std::array<int, 3> rgb{255, 200, 120};
};

/// One panel: axes, series, bands.
struct Panel {
  std::string title;
  std::string x_label = "time [s]";
  std::string y_label;
  std::vector<Series> series;
  std::vector<Band> bands;
  /// Fixed y range when y_min < y_max; otherwise fitted to the data (with a margin). Values
  /// outside a fixed range are never dropped silently: the panel says how many and the extreme.
  double y_min = 0.0;
  double y_max = 0.0;
};

/// A column of panels sharing the x axis, written as one PNG.
struct Figure {
  std::string title;
  std::vector<Panel> panels;
  int width_px = 1400;
  int panel_height_px = 320;
  /// Fixed x range (shared by the panels) when x_min < x_max; otherwise that of the data.
  double x_min = 0.0;
  double x_max = 0.0;
};

/// Where a band's label goes: its row in the label strip above the plot (-1: no label) and its
/// left edge, px.
struct LabelPlace {
  int row = -1;
  int x_px = 0;
};

/// Lays out band labels so that none overlaps another: given each band's start and its label's
/// width in px (width 0: no label), each label starts at its band (shifted left to end at
/// `right_px` when it would run past it) on the first row where it keeps `gap_px` from every
/// label already there. `rows` gets the number of rows used. Pure (the charts' layout; tested).
std::vector<LabelPlace> place_band_labels(const std::vector<std::pair<int, int>>& start_and_width_px,
                                          int right_px, int gap_px, int& rows);

/// True when PNG charts can be written (poise built with OpenCV, i.e. POISE_WITH_CAMERA=ON).
bool png_supported();

/// Writes `figure` to `path` (PNG). Throws std::runtime_error if the file cannot be written, or
/// when !png_supported().
void write_png(const Figure& figure, const std::string& path);

/// A palette of distinguishable colours (index wraps).
std::array<int, 3> palette(int index);

/// "Nice" tick values covering [lo, hi] (about `target` of them).
std::vector<double> nice_ticks(double lo, double hi, int target = 6);

}  // namespace poise::charts
