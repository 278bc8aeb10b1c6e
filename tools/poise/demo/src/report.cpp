#include "poise/demo/report.h"

#include "poise/charts/plot.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
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

/// Roll, pitch, yaw: truth and every filter.
void attitude_chart(const std::string& dir, const ReportInput& input, const AttitudeSeries& att,
                    const std::vector<charts::Band>& episode_bands) {
  charts::Figure f;
  f.title = input.title + ": attitude, estimate vs simulated truth";
  const char* names[3] = {"roll", "pitch", "yaw"};
  for (int axis = 0; axis < 3; ++axis) {
    charts::Panel p;
    p.title = names[axis];
    p.y_label = "deg";
    p.bands = episode_bands;
    int colour = 1;
    for (const auto& filter : input.filters) {
      const auto it = att.find(filter);
      if (it != att.end()) {
        p.series.push_back(attitude_series(filter, it->second, axis, colour, false));
      }
      ++colour;
    }
    const auto truth = att.find("truth");
    if (truth != att.end()) {
      charts::Series t = attitude_series("truth", truth->second, axis, 0, true);
      t.rgb = {0, 0, 0};
      p.series.push_back(t);
    }
    f.panels.push_back(p);
  }
  write_chart(f, dir + "/attitude.png");
}

/// Total attitude error per filter, with the episodes.
void error_chart(const std::string& dir, const ReportInput& input, const ErrorSeries& errors,
                 const std::vector<charts::Band>& episode_bands) {
  charts::Figure f;
  f.title = input.title + ": total attitude error vs truth (bands: scripted episodes)";
  charts::Panel p;
  p.title = "attitude error";
  p.y_label = "deg";
  p.bands = episode_bands;
  int colour = 1;
  double worst = 0.0;
  for (const auto& filter : input.filters) {
    const auto it = errors.find(filter);
    if (it != errors.end()) {
      charts::Series s;
      s.label = filter;
      s.rgb = charts::palette(colour);
      for (const auto& [t, e] : it->second) {
        s.x.push_back(t);
        s.y.push_back(e);
        worst = std::max(worst, e);
      }
      p.series.push_back(s);
    }
    ++colour;
  }
  p.y_min = 0.0;
  p.y_max = std::min(std::max(worst * 1.05, 1.0), 45.0);
  f.panels.push_back(p);
  write_chart(f, dir + "/error.png");
}

/// Magnetic disturbance and magnetometer trust.
void disturbance_chart(const std::string& dir, const ReportInput& input, const AttitudeSeries& att,
                       const std::vector<charts::Band>& episode_bands) {
  charts::Figure f;
  f.title = input.title + ": magnetic disturbance and magnetometer trust";
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
    n.rgb = filter == "truth" ? std::array<int, 3>{0, 0, 0} : charts::palette(colour);
    n.dashed = filter == "truth";
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
  f.title = input.title + ": height and vertical velocity (IMU + barometer)";
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
    sh.rgb = key == "truth" ? std::array<int, 3>{0, 0, 0} : charts::palette(2);
    sh.dashed = key == "truth";
    charts::Series sv = sh;
    charts::Series sb;
    sb.label = "raw baro";
    sb.rgb = {160, 160, 160};
    sb.thickness = 1;
    for (const auto& p : points) {
      sh.x.push_back(p.t_s);
      sh.y.push_back(p.height_m);
      sv.x.push_back(p.t_s);
      sv.y.push_back(p.vertical_velocity_mps);
      sb.x.push_back(p.t_s);
      sb.y.push_back(p.baro_height_m);
    }
    if (key != "truth") {
      h.series.push_back(sb);
    }
    h.series.push_back(sh);
    v.series.push_back(sv);
  }
  f.panels = {h, v};
  write_chart(f, dir + "/altitude.png");
}

/// index.html: the notes, the filters' table, the charts written.
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
  html << "</ul>\n<h2>Filters</h2>\n<table><tr><th>filter</th><th>estimates</th><th>rate [Hz]</th>"
          "<th>attitude RMSE vs truth [deg]</th><th>latency p50 [ms]</th><th>latency p99 [ms]</th>"
          "<th>latency max [ms]</th><th>median NEES</th><th>inside 95 % [%]</th></tr>\n";
  for (const auto& filter : input.filters) {
    const auto it = stats.find(filter);
    if (it == stats.end()) {
      html << "<tr><td>" << filter << "</td><td>0</td><td colspan=7>no estimate received</td></tr>\n";
      continue;
    }
    const FilterStats& s = it->second;
    const double rmse = s.compared ? std::sqrt(s.sum_sq_error / static_cast<double>(s.compared))
                                   : std::numeric_limits<double>::quiet_NaN();
    html << "<tr><td>" << filter << "</td><td>" << s.received << "</td><td>" << fmt(s.rate_hz, 1)
         << "</td><td>" << fmt(rmse, 2) << "</td><td>" << fmt(percentile(s.latencies_ms, 50), 3)
         << "</td><td>" << fmt(percentile(s.latencies_ms, 99), 3) << "</td><td>"
         << fmt(percentile(s.latencies_ms, 100), 3) << "</td><td>" << fmt(s.nees.median(), 2) << "</td><td>"
         << fmt(100.0 * s.nees.fraction_inside(kNees95Dof3), 1) << "</td></tr>\n";
  }
  html << "</table>\n<p>Camera: " << camera.frames << " frames, " << camera.poses
       << " vision poses.</p>\n";
  if (!charts::png_supported()) {
    html << "<p>No charts: this poise was built without OpenCV (-DPOISE_WITH_CAMERA=OFF).</p>\n";
  }
  for (const char* png : {"error.png", "attitude.png", "disturbance.png", "altitude.png"}) {
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
  attitude_chart(dir, input, att, episode_bands);
  error_chart(dir, input, monitor.error_series(), episode_bands);
  disturbance_chart(dir, input, att, episode_bands);
  const auto alt = monitor.altitude_series();
  if (!alt.empty()) {
    altitude_chart(dir, input, alt, episode_bands);
  }
  return write_index(dir, input, monitor);
}

}  // namespace poise::demo
