#include "poise/demo/report.h"

#include "poise/charts/plot.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <sstream>

namespace poise::demo {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

std::vector<charts::Band> bands(const std::vector<Episode>& episodes) {
  static const std::array<std::array<int, 3>, 3> colours{{{255, 190, 120}, {170, 200, 255}, {190, 235, 180}}};
  std::vector<charts::Band> out;
  for (const auto& e : episodes) {
    out.push_back({e.start_s, e.end_s, e.label, colours[static_cast<std::size_t>(e.colour % 3)]});
  }
  return out;
}

charts::Series attitude_series(const std::string& label, const std::vector<AttitudePoint>& points,
                               int axis, int colour, bool dashed) {
  charts::Series s;
  s.label = label;
  s.rgb = charts::palette(colour);
  s.dashed = dashed;
  double last = std::numeric_limits<double>::quiet_NaN();
  for (const auto& p : points) {
    double v = p.rpy_rad(axis) * kRadToDeg;
    if (axis == 2 && std::isfinite(last) && std::abs(v - last) > 180.0) {
      s.x.push_back(p.t_s);
      s.y.push_back(std::numeric_limits<double>::quiet_NaN());  // break the line at the wrap
    }
    last = v;
    s.x.push_back(p.t_s);
    s.y.push_back(v);
  }
  return s;
}

std::string html_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string fmt(double v, int decimals = 2) {
  if (!std::isfinite(v)) {
    return "-";
  }
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  return buf;
}

/// The charts are left out when poise was built without OpenCV (POISE_WITH_CAMERA=OFF); the page
/// says so.
void write_chart(const charts::Figure& figure, const std::string& path) {
  if (charts::png_supported()) {
    charts::write_png(figure, path);
  }
}

using AttitudeSeries = std::map<std::string, std::vector<AttitudePoint>>;
using AltitudeSeries = std::map<std::string, std::vector<AltitudePoint>>;
using ErrorSeries = std::map<std::string, std::vector<std::pair<double, double>>>;

/// The simulated truth as drawn under the estimates: thick and light, so that a filter on top of
/// it stays visible.
constexpr std::array<int, 3> kTruthRgb{165, 165, 165};
constexpr int kTruthThickness = 10;

/// Line width of the i-th estimate drawn over the truth: the earlier ones wider, so that filters
/// that agree within a pixel still show as a coloured edge around the next (6, 3, then 2 px).
int layered_thickness(int i) { return std::max(2, 6 - 3 * i); }

/// Roll, pitch, yaw: truth (underneath) and every filter.
void attitude_chart(const std::string& dir, const ReportInput& input, const AttitudeSeries& att,
                    const std::vector<charts::Band>& episode_bands) {
  charts::Figure f;
  f.title = input.simulated_truth
                ? input.title + ": attitude, each filter (thin, coloured) over the simulated truth (thick grey)"
                : input.title + ": attitude of each filter (real IMU: no truth)";
  const char* names[3] = {"roll", "pitch", "yaw"};
  for (int axis = 0; axis < 3; ++axis) {
    charts::Panel p;
    p.title = names[axis];
    p.y_label = "deg";
    p.bands = episode_bands;
    const auto truth = att.find("truth");
    if (truth != att.end()) {
      charts::Series t = attitude_series("truth", truth->second, axis, 0, false);
      t.rgb = kTruthRgb;
      t.thickness = kTruthThickness;
      p.series.push_back(t);
    }
    int colour = 1;
    for (const auto& filter : input.filters) {
      const auto it = att.find(filter);
      if (it != att.end()) {
        charts::Series e = attitude_series(filter, it->second, axis, colour, false);
        e.thickness = layered_thickness(colour - 1);
        p.series.push_back(e);
      }
      ++colour;
    }
    f.panels.push_back(p);
  }
  write_chart(f, dir + "/attitude.png");
}

double rms(const std::vector<std::pair<double, double>>& errors) {
  double sum = 0.0;
  for (const auto& [t, e] : errors) {
    sum += e * e;
  }
  return errors.empty() ? std::numeric_limits<double>::quiet_NaN() : std::sqrt(sum / static_cast<double>(errors.size()));
}

double largest(const std::vector<std::pair<double, double>>& errors) {
  double worst = 0.0;
  for (const auto& [t, e] : errors) {
    worst = std::max(worst, e);
  }
  return worst;
}

/// One panel of an error over time, on a scale that holds all of it (0 to the largest value):
/// nothing is clipped.
charts::Panel error_panel(const std::string& title, const std::string& unit,
                          const std::vector<std::pair<double, double>>& errors, std::array<int, 3> rgb,
                          const std::vector<charts::Band>& episode_bands) {
  charts::Panel p;
  p.title = title;
  p.y_label = unit;
  p.bands = episode_bands;
  charts::Series s;  // no legend: the panel's title names it
  s.rgb = rgb;
  for (const auto& [t, e] : errors) {
    s.x.push_back(t);
    s.y.push_back(e);
  }
  p.series.push_back(s);
  p.y_min = 0.0;
  p.y_max = std::max(largest(errors) * 1.08, 1e-6);
  return p;
}

/// Total attitude error of each filter, each in its own panel and on its own scale (a filter
/// 100x worse than another no longer flattens it), with the episodes.
void error_chart(const std::string& dir, const ReportInput& input, const ErrorSeries& errors,
                 const std::vector<charts::Band>& episode_bands) {
  charts::Figure f;
  f.title = input.title + ": attitude error vs truth, each filter on its own scale";
  f.panel_height_px = 300;
  int colour = 1;
  for (const auto& filter : input.filters) {
    const auto it = errors.find(filter);
    if (it != errors.end()) {
      f.panels.push_back(error_panel(filter + ": attitude error (RMSE " + fmt(rms(it->second), 2) + " deg, largest " +
                                         fmt(largest(it->second), 2) + " deg)",
                                     "deg", it->second, charts::palette(colour), episode_bands));
    }
    ++colour;
  }
  if (!f.panels.empty()) {
    write_chart(f, dir + "/error.png");
  }
}

/// One series per pose filter and the truth (underneath, thick grey), the point of each sample
/// from `xy`.
void add_position_series(charts::Panel& p, const std::map<std::string, std::vector<PositionPoint>>& positions,
                         const std::function<std::pair<double, double>(const PositionPoint&)>& xy) {
  for (const auto& [name, points] : positions) {
    charts::Series s;
    s.label = name;
    const bool truth = name == "truth";
    s.rgb = truth ? kTruthRgb : charts::palette(2);
    s.thickness = truth ? kTruthThickness : 2;
    for (const auto& pt : points) {
      const auto [x, y] = xy(pt);
      s.x.push_back(x);
      s.y.push_back(y);
    }
    if (truth) {
      p.series.insert(p.series.begin(), s);
    } else {
      p.series.push_back(s);
    }
  }
}

/// The selective EKF's position: east, north, up over the truth, and its position error.
void position_chart(const std::string& dir, const ReportInput& input,
                    const std::map<std::string, std::vector<PositionPoint>>& positions,
                    const ErrorSeries& position_errors, const std::vector<charts::Band>& episode_bands) {
  charts::Figure f;
  f.title = input.simulated_truth
                ? input.title + ": position, each pose filter (thin) over the simulated truth (thick grey)"
                : input.title + ": position of each pose filter (real IMU: no truth)";
  f.panel_height_px = 290;
  const char* names[3] = {"east", "north", "up"};
  for (int axis = 0; axis < 3; ++axis) {
    charts::Panel p;
    p.title = std::string(names[axis]) + " position";
    p.y_label = "m";
    p.bands = episode_bands;
    add_position_series(p, positions, [axis](const PositionPoint& pt) {
      return std::pair<double, double>{pt.t_s, pt.p_m(axis)};
    });
    f.panels.push_back(p);
  }
  for (const auto& [name, errors] : position_errors) {
    f.panels.push_back(error_panel(name + ": position error (RMSE " + fmt(rms(errors), 3) + " m, largest " +
                                       fmt(largest(errors), 3) + " m)",
                                   "m", errors, charts::palette(2), episode_bands));
  }
  write_chart(f, dir + "/position.png");
}

/// The path seen from above (north over east), one metre the same length on both axes.
void path_chart(const std::string& dir, const ReportInput& input,
                const std::map<std::string, std::vector<PositionPoint>>& positions) {
  double e_lo = std::numeric_limits<double>::infinity();
  double e_hi = -e_lo;
  double n_lo = e_lo;
  double n_hi = -e_lo;
  charts::Panel p;
  p.title = "path from above (equal scales)";
  p.x_label = "east [m]";
  p.y_label = "north [m]";
  add_position_series(p, positions, [](const PositionPoint& pt) {
    return std::pair<double, double>{pt.p_m.x(), pt.p_m.y()};
  });
  for (const auto& [name, points] : positions) {
    for (const auto& pt : points) {
      if (pt.p_m.allFinite()) {
        e_lo = std::min(e_lo, pt.p_m.x());
        e_hi = std::max(e_hi, pt.p_m.x());
        n_lo = std::min(n_lo, pt.p_m.y());
        n_hi = std::max(n_hi, pt.p_m.y());
      }
    }
  }
  if (!std::isfinite(e_lo)) {
    return;
  }
  // Plot area 900 - 120 px wide, 760 - 90 - 50 px high (charts' margins): equal metres per pixel.
  charts::Figure f;
  f.title = input.title + ": path";
  f.width_px = 900;
  f.panel_height_px = 760;
  const double plot_w = 900.0 - 120.0;
  const double plot_h = 760.0 - 90.0;
  const double m_per_px = std::max({(e_hi - e_lo) / plot_w, (n_hi - n_lo) / plot_h, 1e-3}) * 1.1;
  const double e_mid = 0.5 * (e_lo + e_hi);
  const double n_mid = 0.5 * (n_lo + n_hi);
  f.x_min = e_mid - 0.5 * m_per_px * plot_w;
  f.x_max = e_mid + 0.5 * m_per_px * plot_w;
  p.y_min = n_mid - 0.5 * m_per_px * plot_h;
  p.y_max = n_mid + 0.5 * m_per_px * plot_h;
  f.panels.push_back(p);
  write_chart(f, dir + "/path.png");
}

/// Magnetic disturbance and magnetometer trust.
void disturbance_chart(const std::string& dir, const ReportInput& input, const AttitudeSeries& att,
                       const std::vector<charts::Band>& episode_bands) {
  charts::Figure f;
  f.title = input.title + ": magnetic disturbance and magnetometer trust (truth: thick grey)";
  charts::Panel norm;
  norm.title = "disturbance norm";
  norm.y_label = "uT";
  norm.bands = episode_bands;
  charts::Panel trust;
  trust.title = "magnetometer trusted (1 = used for heading)";
  trust.bands = episode_bands;
  trust.y_min = -0.1;
  trust.y_max = 1.1;
  int colour = 0;
  for (const std::string& filter : [&] {
         std::vector<std::string> v{"truth"};
         v.insert(v.end(), input.filters.begin(), input.filters.end());
         return v;
       }()) {
    const auto it = att.find(filter);
    if (it == att.end() || filter == "gauss_newton") {
      ++colour;
      continue;
    }
    charts::Series n;
    n.label = filter;
    n.rgb = filter == "truth" ? kTruthRgb : charts::palette(colour);
    n.thickness = filter == "truth" ? kTruthThickness : layered_thickness(colour - 1);  // truth first: underneath
    charts::Series tr = n;
    for (const auto& pt : it->second) {
      n.x.push_back(pt.t_s);
      n.y.push_back(pt.disturbance_norm_ut);
      tr.x.push_back(pt.t_s);
      tr.y.push_back(pt.mag_trusted ? 1.0 : 0.0);
    }
    if (filter != "selective_ekf") {  // it does not estimate the disturbance vector
      norm.series.push_back(n);
    }
    trust.series.push_back(tr);
    ++colour;
  }
  f.panels = {norm, trust};
  write_chart(f, dir + "/disturbance.png");
}

/// Altitude and vertical velocity.
void altitude_chart(const std::string& dir, const ReportInput& input, const AltitudeSeries& alt,
                    const std::vector<charts::Band>& episode_bands) {
  charts::Figure f;
  f.title = input.title + ": height and vertical velocity (IMU + barometer; truth: thick grey)";
  charts::Panel h;
  h.title = "height above start";
  h.y_label = "m";
  h.bands = episode_bands;
  charts::Panel v;
  v.title = "vertical velocity";
  v.y_label = "m/s";
  v.bands = episode_bands;
  for (const auto& [key, points] : alt) {
    charts::Series sh;
    sh.label = key == "truth" ? "truth" : "altitude filter";
    sh.rgb = key == "truth" ? kTruthRgb : charts::palette(2);
    sh.thickness = key == "truth" ? kTruthThickness : 2;
    charts::Series sv = sh;
    charts::Series sb;
    sb.label = "raw baro";
    sb.rgb = {140, 185, 235};  // light blue: the noisy input, drawn first
    sb.thickness = 1;
    for (const auto& p : points) {
      sh.x.push_back(p.t_s);
      sh.y.push_back(p.height_m);
      sv.x.push_back(p.t_s);
      sv.y.push_back(p.vertical_velocity_mps);
      sb.x.push_back(p.t_s);
      sb.y.push_back(p.baro_height_m);
    }
    if (key == "truth") {  // underneath the estimates, over the raw barometric heights
      const bool baro_first = !h.series.empty() && h.series.front().label == "raw baro";
      h.series.insert(h.series.begin() + (baro_first ? 1 : 0), sh);
      v.series.insert(v.series.begin(), sv);
    } else {
      h.series.push_back(sb);
      h.series.push_back(sh);
      v.series.push_back(sv);
    }
  }
  f.panels = {h, v};
  write_chart(f, dir + "/altitude.png");
}

/// RMS of the errors whose time falls inside (or, `inside` false, outside every one of) `episodes`.
double rms_in(const std::vector<std::pair<double, double>>& errors, const std::vector<Episode>& episodes, bool inside) {
  std::vector<std::pair<double, double>> kept;
  for (const auto& te : errors) {
    bool in = false;
    for (const auto& e : episodes) {
      in = in || (te.first >= e.start_s && te.first < e.end_s);
    }
    if (in == inside) {
      kept.push_back(te);
    }
  }
  return rms(kept);
}

/// What each figure of the report is (the page says it under the tables).
const char* kDefinitions =
    "<h2>What the figures are</h2>\n<ul>\n"
    "<li><b>attitude error</b>: the angle of the rotation between a filter's estimated orientation and the "
    "simulated truth for the same IMU sample (matched by the sample's sequence number, header.seq), in degrees: "
    "roll, pitch and yaw errors together. <b>RMSE</b>: the root mean square of it over every matched sample; "
    "<b>largest</b>: its maximum.</li>\n"
    "<li><b>median NEES</b>, <b>inside 95 %</b>: the consistency of each filter's published attitude_covariance "
    "with its error against the truth: NEES = e^T P^-1 e, e the world-frame rotation vector (rad) from the "
    "estimate to the truth, P the published covariance (rad^2); for a right covariance it follows a chi-square law "
    "with 3 degrees of freedom: median about 2.37, 95 % of samples inside the 95 % ellipsoid (NEES <= 7.82). As "
    "poise eval broad prints it.</li>\n"
    "<li><b>position error</b>: the distance between the selective EKF's estimated body position (pose/selective_ekf) "
    "and the simulated truth's (truth/pose) for the same IMU sample, in metres.</li>\n"
    "<li><b>estimates</b>: estimates received; <b>rate</b>: estimates received per second of the run.</li>\n"
    "<li><b>latency</b>: for each estimate, the time from its IMU sample's stamp to the moment the report's "
    "subscriber, in the same process, received the estimate over DDS; p50 / p99 / max are its median, 99th "
    "percentile and maximum in milliseconds. The stamp is the sample's time on the board's clock mapped onto this "
    "host's monotonic clock by the serial driver, along the lower envelope of the lines' arrivals (a stamp is never "
    "after its line arrived): so the figure holds the parsing, the DDS hop to the filter, the filter's step, the DDS "
    "hop back and any delay of a line beyond the quickest ones, but not the serial line's constant transfer "
    "time.</li>\n"
    "<li><b>bands</b> on the charts: the scripted episodes of the simulated scenario, labelled above each panel "
    "(magnet near / attached: a magnetic disturbance; tag lost, camera blackout: no vision pose; stairs: a climb).</li>\n"
    "<li>Time on every chart: seconds since the report's subscriber started.</li>\n"
    "</ul>\n";

/// index.html: the notes, the filters' table, the position table, the definitions, the charts.
// not split: one page written top to bottom from the same snapshot of the monitor.
std::string write_index(const std::string& dir, const ReportInput& input, const PipelineMonitor& monitor) {
  const auto stats = monitor.filter_stats();
  const auto camera = monitor.camera_stats();
  std::ostringstream html;
  html << "<!doctype html><html><head><meta charset=\"utf-8\"><title>" << html_escape(input.title)
       << "</title><style>body{font-family:sans-serif;margin:2em;max-width:1450px}"
          "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px 10px;text-align:right}"
          "th{background:#eee}td:first-child{text-align:left}img{max-width:100%;border:1px solid #ddd;"
          "margin:8px 0}</style></head><body>\n";
  html << "<h1>" << html_escape(input.title) << "</h1>\n<ul>";
  for (const auto& n : input.notes) {
    html << "<li>" << html_escape(n) << "</li>";
  }
  html << "</ul>\n";
  if (!input.simulated_truth) {
    html << "<p>Real IMU: there is no truth to compare with, so no error is computed; the charts show the "
            "estimates.</p>\n";
  }
  html << "<h2>Filters</h2>\n<table><tr><th>filter</th><th>estimates</th><th>rate [Hz]</th>";
  if (input.simulated_truth) {
    html << "<th>attitude RMSE vs truth [deg]</th>";
  }
  html << "<th>latency p50 [ms]</th><th>latency p99 [ms]</th><th>latency max [ms]</th>";
  if (input.simulated_truth) {
    html << "<th>median NEES</th><th>inside 95 % [%]</th>";
  }
  html << "</tr>\n";
  for (const auto& filter : input.filters) {
    const auto it = stats.find(filter);
    if (it == stats.end()) {
      html << "<tr><td>" << filter << "</td><td>0</td><td colspan=" << (input.simulated_truth ? 7 : 4)
           << ">no estimate received</td></tr>\n";
      continue;
    }
    const FilterStats& s = it->second;
    const double rmse = s.compared ? std::sqrt(s.sum_sq_error / static_cast<double>(s.compared))
                                   : std::numeric_limits<double>::quiet_NaN();
    html << "<tr><td>" << filter << "</td><td>" << s.received << "</td><td>" << fmt(s.rate_hz, 1) << "</td>";
    if (input.simulated_truth) {
      html << "<td>" << fmt(rmse, 2) << "</td>";
    }
    html << "<td>" << fmt(percentile(s.latencies_ms, 50), 3) << "</td><td>" << fmt(percentile(s.latencies_ms, 99), 3)
         << "</td><td>" << fmt(percentile(s.latencies_ms, 100), 3) << "</td>";
    if (input.simulated_truth) {
      html << "<td>" << fmt(s.nees.median(), 2) << "</td><td>" << fmt(100.0 * s.nees.fraction_inside(kNees95Dof3), 1)
           << "</td>";
    }
    html << "</tr>\n";
  }
  html << "</table>\n";
  const auto position_errors = monitor.position_errors();
  if (input.simulated_truth && !position_errors.empty()) {
    std::vector<std::string> labels;  // the distinct episodes, in order of first appearance
    for (const auto& e : input.episodes) {
      if (std::find(labels.begin(), labels.end(), e.label) == labels.end()) {
        labels.push_back(e.label);
      }
    }
    html << "<h2>Position</h2>\n<table><tr><th>filter</th><th>RMSE [m]</th><th>largest [m]</th>"
            "<th>outside every episode [m RMS]</th>";
    for (const auto& l : labels) {
      html << "<th>during " << html_escape(l) << " [m RMS]</th>";
    }
    html << "</tr>\n";
    for (const auto& [name, errors] : position_errors) {
      html << "<tr><td>" << name << "</td><td>" << fmt(rms(errors), 3) << "</td><td>" << fmt(largest(errors), 3)
           << "</td><td>" << fmt(rms_in(errors, input.episodes, false), 3) << "</td>";
      for (const auto& l : labels) {
        std::vector<Episode> these;
        std::copy_if(input.episodes.begin(), input.episodes.end(), std::back_inserter(these),
                     [&](const Episode& e) { return e.label == l; });
        html << "<td>" << fmt(rms_in(errors, these, true), 3) << "</td>";
      }
      html << "</tr>\n";
    }
    html << "</table>\n";
  }
  html << "<p>Camera: " << camera.frames << " frames, " << camera.poses << " vision poses.</p>\n";
  html << kDefinitions;
  if (!charts::png_supported()) {
    html << "<p>No charts: this poise was built without OpenCV (-DPOISE_WITH_CAMERA=OFF).</p>\n";
  }
  for (const char* png : {"error.png", "position.png", "path.png", "attitude.png", "disturbance.png", "altitude.png"}) {
    if (std::filesystem::exists(dir + "/" + png)) {
      html << "<img src=\"" << png << "\" alt=\"" << png << "\">\n";
    }
  }
  html << "</body></html>\n";
  const std::string index = dir + "/index.html";
  std::ofstream out(index);
  out << html.str();
  if (!out) {
    throw std::runtime_error("cannot write " + index);
  }
  return index;
}

}  // namespace

std::string write_report(const std::string& dir, const ReportInput& input, const PipelineMonitor& monitor) {
  std::filesystem::create_directories(dir);
  const auto att = monitor.attitude_series();
  const auto episode_bands = bands(input.episodes);
  for (const char* png : {"error.png", "position.png", "path.png"}) {
    std::filesystem::remove(dir + "/" + png);  // a chart this run does not draw must not stay from an earlier one
  }
  attitude_chart(dir, input, att, episode_bands);
  if (input.simulated_truth) {
    error_chart(dir, input, monitor.error_series(), episode_bands);
  }
  const auto positions = monitor.position_series();
  // a pose filter ran, and its position means something: against a truth, or fed by vision poses
  // (without either, the selective EKF only holds its position: nothing to chart)
  const bool pose_filter = positions.size() > (positions.count("truth") != 0 ? 1U : 0U);
  if (pose_filter && (positions.count("truth") != 0 || monitor.camera_stats().poses > 0)) {
    position_chart(dir, input, positions, input.simulated_truth ? monitor.position_errors() : ErrorSeries{},
                   episode_bands);
    path_chart(dir, input, positions);
  }
  disturbance_chart(dir, input, att, episode_bands);
  const auto alt = monitor.altitude_series();
  if (!alt.empty()) {
    altitude_chart(dir, input, alt, episode_bands);
  }
  return write_index(dir, input, monitor);
}

}  // namespace poise::demo
