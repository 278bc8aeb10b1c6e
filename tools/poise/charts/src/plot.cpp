#include "poise/charts/plot.h"

#if POISE_WITH_OPENCV
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#endif

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace poise::charts {
#if POISE_WITH_OPENCV
namespace {

constexpr int kMarginLeft = 90;
constexpr int kMarginRight = 30;
constexpr int kMarginTop = 40;
constexpr int kMarginBottom = 50;
constexpr int kFigureTitleHeight = 50;
const cv::Scalar kAxisColour(60, 60, 60);
const cv::Scalar kGridColour(225, 225, 225);
const cv::Scalar kTextColour(30, 30, 30);

cv::Scalar bgr(const std::array<int, 3>& rgb) { return cv::Scalar(rgb[2], rgb[1], rgb[0]); }

std::string format_tick(double v, double step) {
  char buf[32];
  const int decimals = step >= 1.0 ? 0 : static_cast<int>(std::ceil(-std::log10(step)));
  std::snprintf(buf, sizeof buf, "%.*f", std::min(decimals, 6), v);
  return buf;
}

void text(cv::Mat& img, const std::string& s, cv::Point at, double scale, int thickness = 1,
          bool centre = false) {
  int baseline = 0;
  const cv::Size size = cv::getTextSize(s, cv::FONT_HERSHEY_SIMPLEX, scale, thickness, &baseline);
  if (centre) {
    at.x -= size.width / 2;
  }
  cv::putText(img, s, at, cv::FONT_HERSHEY_SIMPLEX, scale, kTextColour, thickness, cv::LINE_AA);
}

// not split: one panel drawn back to front (frame, bands, grid, series, legend) on shared scales.
void draw_panel(cv::Mat& img, const Panel& panel, const cv::Rect& area, double x_lo, double x_hi) {
  double y_lo = panel.y_min;
  double y_hi = panel.y_max;
  const bool fixed = y_lo < y_hi;
  if (!fixed) {
    y_lo = std::numeric_limits<double>::infinity();
    y_hi = -std::numeric_limits<double>::infinity();
    for (const auto& s : panel.series) {
      for (double v : s.y) {
        if (std::isfinite(v)) {
          y_lo = std::min(y_lo, v);
          y_hi = std::max(y_hi, v);
        }
      }
    }
    if (!std::isfinite(y_lo)) {
      y_lo = 0.0;
      y_hi = 1.0;
    }
    const double pad = std::max(1e-9, (y_hi - y_lo) * 0.08);
    y_lo -= pad;
    y_hi += pad;
    if (y_hi - y_lo < 1e-6) {
      y_lo -= 0.5;
      y_hi += 0.5;
    }
  }
  // A fixed range never hides values silently: count what falls outside it.
  std::size_t clipped = 0;
  double extreme = 0.0;
  if (fixed) {
    for (const auto& s : panel.series) {
      for (double v : s.y) {
        if (std::isfinite(v) && (v > y_hi || v < y_lo)) {
          ++clipped;
          extreme = std::abs(v) > std::abs(extreme) ? v : extreme;
        }
      }
    }
  }
  const int plot_x = area.x + kMarginLeft;
  const int plot_w = area.width - kMarginLeft - kMarginRight;
  auto px = [&](double x) {
    return plot_x + static_cast<int>(std::lround((x - x_lo) / (x_hi - x_lo) * plot_w));
  };

  // Band labels in a strip of their own above the plot (never over the data), each on the first
  // row where it runs into no other label (overlapping episodes, e.g. "stairs down" during
  // "magnet attached", stack), each row showing the band's extent in its colour.
  constexpr double kBandLabelScale = 0.42;
  constexpr int kBandLabelRowPx = 16;
  std::vector<std::pair<int, int>> starts;  // per band: start px, label width px (0: no label)
  std::vector<std::pair<int, int>> spans;   // per band: clamped [a, b] px
  for (const auto& band : panel.bands) {
    const int a = std::clamp(px(band.x0), plot_x, plot_x + plot_w);
    const int b = std::clamp(px(band.x1), plot_x, plot_x + plot_w);
    int baseline = 0;
    const int label_w = (b > a && !band.label.empty())
                            ? cv::getTextSize(band.label, cv::FONT_HERSHEY_SIMPLEX, kBandLabelScale, 1, &baseline).width + 8
                            : 0;
    // a row holds the label and the band's extent, which neither another label nor band may share
    starts.emplace_back(a, label_w > 0 ? std::max(label_w, b - a) : 0);
    spans.emplace_back(a, b);
  }
  int label_rows = 0;
  const auto places = place_band_labels(starts, plot_x + plot_w, 6, label_rows);
  const int strip_top = area.y + kMarginTop;
  const cv::Rect plot(plot_x, strip_top + label_rows * kBandLabelRowPx + (label_rows > 0 ? 4 : 0), plot_w,
                      area.y + area.height - kMarginBottom - (strip_top + label_rows * kBandLabelRowPx +
                                                              (label_rows > 0 ? 4 : 0)));
  auto py = [&](double y) {
    const double c = std::clamp(y, y_lo, y_hi);
    return plot.y + plot.height - static_cast<int>(std::lround((c - y_lo) / (y_hi - y_lo) * plot.height));
  };
  for (std::size_t i = 0; i < panel.bands.size(); ++i) {
    const auto& band = panel.bands[i];
    const auto [a, b] = spans[i];
    if (b <= a) {
      continue;
    }
    cv::Mat roi = img(cv::Rect(a, plot.y, b - a, plot.height));
    cv::Mat fill(roi.size(), roi.type(), bgr(band.rgb));
    cv::addWeighted(fill, 0.35, roi, 0.65, 0.0, roi);
    if (places[i].row >= 0) {
      const int top = strip_top + places[i].row * kBandLabelRowPx;
      cv::Mat tag = img(cv::Rect(a, top + 1, b - a, kBandLabelRowPx - 2));
      cv::Mat tag_fill(tag.size(), tag.type(), bgr(band.rgb));
      cv::addWeighted(tag_fill, 0.6, tag, 0.4, 0.0, tag);
      text(img, band.label, {places[i].x_px + 4, top + kBandLabelRowPx - 4}, kBandLabelScale);
    }
  }
  const auto y_ticks = nice_ticks(y_lo, y_hi, 5);
  const double y_step = y_ticks.size() > 1 ? y_ticks[1] - y_ticks[0] : 1.0;
  for (double t : y_ticks) {
    cv::line(img, {plot.x, py(t)}, {plot.x + plot.width, py(t)}, kGridColour, 1);
    text(img, format_tick(t, y_step), {area.x + 8, py(t) + 5}, 0.45);
  }
  const auto x_ticks = nice_ticks(x_lo, x_hi, 10);
  const double x_step = x_ticks.size() > 1 ? x_ticks[1] - x_ticks[0] : 1.0;
  for (double t : x_ticks) {
    cv::line(img, {px(t), plot.y}, {px(t), plot.y + plot.height}, kGridColour, 1);
    text(img, format_tick(t, x_step), {px(t), plot.y + plot.height + 20}, 0.45, 1, true);
  }
  cv::rectangle(img, plot, kAxisColour, 1);

  for (const auto& s : panel.series) {
    const std::size_t n = std::min(s.x.size(), s.y.size());
    // Decimate to about two points per pixel column.
    const std::size_t stride = std::max<std::size_t>(1, n / static_cast<std::size_t>(2 * plot.width));
    std::vector<cv::Point> run;
    auto flush = [&] {
      if (run.size() >= 2) {
        if (s.dashed) {
          for (std::size_t i = 1; i < run.size(); i += 2) {
            cv::line(img, run[i - 1], run[i], bgr(s.rgb), s.thickness, cv::LINE_AA);
          }
        } else {
          cv::polylines(img, run, false, bgr(s.rgb), s.thickness, cv::LINE_AA);
        }
      }
      run.clear();
    };
    for (std::size_t i = 0; i < n; i += stride) {
      if (!std::isfinite(s.y[i]) || !std::isfinite(s.x[i])) {
        flush();
        continue;
      }
      run.emplace_back(px(s.x[i]), py(s.y[i]));
    }
    flush();
  }
  text(img, panel.title, {plot.x, area.y + 26}, 0.62, 2);
  if (clipped > 0) {
    char note[160];
    std::snprintf(note, sizeof note, "clipped: %zu values outside [%g, %g] not shown (extreme %.3g)", clipped,
                  y_lo, y_hi, extreme);
    int baseline = 0;
    const int title_w = cv::getTextSize(panel.title, cv::FONT_HERSHEY_SIMPLEX, 0.62, 2, &baseline).width;
    cv::putText(img, note, {plot.x + title_w + 16, area.y + 26}, cv::FONT_HERSHEY_SIMPLEX, 0.45,
                cv::Scalar(0, 0, 200), 1, cv::LINE_AA);
  }
  text(img, panel.y_label, {area.x + 8, area.y + 26}, 0.45);
  text(img, panel.x_label, {plot.x + plot.width / 2, plot.y + plot.height + 42}, 0.45, 1, true);
  // Legend, top right.
  int lx = plot.x + plot.width - 10;
  for (auto it = panel.series.rbegin(); it != panel.series.rend(); ++it) {
    if (it->label.empty()) {
      continue;  // a panel of one series names it in its title
    }
    int baseline = 0;
    const int w = cv::getTextSize(it->label, cv::FONT_HERSHEY_SIMPLEX, 0.45, 1, &baseline).width;
    lx -= w + 36;
    cv::line(img, {lx, area.y + 22}, {lx + 24, area.y + 22}, bgr(it->rgb), 3, cv::LINE_AA);
    text(img, it->label, {lx + 28, area.y + 27}, 0.45);
  }
}

}  // namespace
#endif

std::vector<LabelPlace> place_band_labels(const std::vector<std::pair<int, int>>& start_and_width_px,
                                          int right_px, int gap_px, int& rows) {
  std::vector<std::size_t> order(start_and_width_px.size());
  for (std::size_t i = 0; i < order.size(); ++i) {
    order[i] = i;
  }
  std::stable_sort(order.begin(), order.end(), [&](std::size_t l, std::size_t r) {
    return start_and_width_px[l].first < start_and_width_px[r].first;
  });
  std::vector<LabelPlace> out(start_and_width_px.size());
  std::vector<std::vector<std::pair<int, int>>> taken;  // per row: [x0, x1) of its labels
  for (const std::size_t i : order) {
    const auto [start, width] = start_and_width_px[i];
    if (width <= 0) {
      continue;
    }
    const int x0 = std::min(start, right_px - width);
    const int x1 = x0 + width;
    std::size_t row = 0;
    const auto free = [&](std::size_t r) {
      for (const auto& [a, b] : taken[r]) {
        if (x0 < b + gap_px && a < x1 + gap_px) {
          return false;
        }
      }
      return true;
    };
    while (row < taken.size() && !free(row)) {
      ++row;
    }
    if (row == taken.size()) {
      taken.emplace_back();
    }
    taken[row].emplace_back(x0, x1);
    out[i] = {static_cast<int>(row), x0};
  }
  rows = static_cast<int>(taken.size());
  return out;
}

std::vector<double> nice_ticks(double lo, double hi, int target) {
  std::vector<double> ticks;
  if (!(hi > lo) || target < 1) {
    return ticks;
  }
  const double raw = (hi - lo) / target;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  double step = magnitude;
  for (double m : {1.0, 2.0, 2.5, 5.0, 10.0}) {
    step = m * magnitude;
    if (step >= raw) {
      break;
    }
  }
  for (double t = std::ceil(lo / step) * step; t <= hi + step * 1e-9; t += step) {
    ticks.push_back(std::abs(t) < step * 1e-9 ? 0.0 : t);
  }
  return ticks;
}

std::array<int, 3> palette(int index) {
  static const std::array<std::array<int, 3>, 8> colours{{{31, 119, 180},
                                                          {214, 39, 40},
                                                          {44, 160, 44},
                                                          {255, 127, 14},
                                                          {148, 103, 189},
                                                          {140, 86, 75},
                                                          {227, 119, 194},
                                                          {23, 190, 207}}};
  return colours[static_cast<std::size_t>(index) % colours.size()];
}

#if POISE_WITH_OPENCV
bool png_supported() { return true; }

void write_png(const Figure& figure, const std::string& path) {
  const int height = kFigureTitleHeight + figure.panel_height_px * static_cast<int>(figure.panels.size());
  cv::Mat img(std::max(height, kFigureTitleHeight + 10), figure.width_px, CV_8UC3,
              cv::Scalar(255, 255, 255));
  double x_lo = std::numeric_limits<double>::infinity();
  double x_hi = -std::numeric_limits<double>::infinity();
  for (const auto& p : figure.panels) {
    for (const auto& s : p.series) {
      for (double x : s.x) {
        if (std::isfinite(x)) {
          x_lo = std::min(x_lo, x);
          x_hi = std::max(x_hi, x);
        }
      }
    }
  }
  if (figure.x_min < figure.x_max) {
    x_lo = figure.x_min;
    x_hi = figure.x_max;
  }
  if (!(x_hi > x_lo)) {
    x_lo = 0.0;
    x_hi = 1.0;
  }
  text(img, figure.title, {20, 34}, 0.85, 2);
  for (std::size_t i = 0; i < figure.panels.size(); ++i) {
    const cv::Rect area(0, kFigureTitleHeight + static_cast<int>(i) * figure.panel_height_px,
                        figure.width_px, figure.panel_height_px);
    draw_panel(img, figure.panels[i], area, x_lo, x_hi);
  }
  if (!cv::imwrite(path, img)) {
    throw std::runtime_error("cannot write the chart '" + path + "'");
  }
}

#else
bool png_supported() { return false; }

void write_png(const Figure& /*figure*/, const std::string& path) {
  throw std::runtime_error("cannot write the chart '" + path +
                           "': poise was built without OpenCV (-DPOISE_WITH_CAMERA=OFF)");
}
#endif

}  // namespace poise::charts
