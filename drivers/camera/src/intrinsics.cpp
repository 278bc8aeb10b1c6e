#include "poise/camera/intrinsics.h"
#include "poise/core/yaml_params.h"

#include <yaml-cpp/yaml.h>

#include <opencv2/core/mat.hpp>

#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

namespace poise::camera {
namespace {

constexpr double kMaxAspect = 4.0;  // fx/fy beyond this (or 1/this) is a unit or typing error
// Largest image side a calibration may state: beyond any camera sensor made (the largest are
// ~16k px); larger values are typing errors and would size per-pixel maps in gigabytes.
constexpr int kMaxCalibratedSidePx = 32768;

bool finite(double v) { return std::isfinite(v); }

std::string read_text(const std::string& path) {
  return read_yaml_text<ConfigError>(path, "cannot read intrinsics file '" + path +
                                               "': check the path (expected an OpenCV calibration YAML or a ROS "
                                               "camera_info YAML)");
}

bool looks_like_opencv(const std::string& text) {
  return text.rfind("%YAML:", 0) == 0 || text.find("!!opencv-matrix") != std::string::npos;
}

void fill_from_matrix(CameraIntrinsics& out, const cv::Mat& k, const cv::Mat& d,
                      const std::string& source) {
  if (k.empty()) {
    throw ConfigError(source + ": no camera matrix (expected key camera_matrix, cameraMatrix or K)");
  }
  if (k.rows != 3 || k.cols != 3) {
    throw ConfigError(source + ": camera matrix is " + std::to_string(k.rows) + "x" +
                      std::to_string(k.cols) + ", expected 3x3");
  }
  cv::Mat k64;
  k.convertTo(k64, CV_64F);
  // written so that a NaN entry fails the test too
  if (!(k64.at<double>(1, 0) == 0.0 && k64.at<double>(2, 0) == 0.0 && k64.at<double>(2, 1) == 0.0 &&
        std::abs(k64.at<double>(2, 2) - 1.0) <= 1e-9)) {
    throw ConfigError(source +
                      ": camera matrix is not of the form [fx s cx; 0 fy cy; 0 0 1] (is it "
                      "transposed or a projection matrix?)");
  }
  out.fx_px = k64.at<double>(0, 0);
  out.skew = k64.at<double>(0, 1);
  out.cx_px = k64.at<double>(0, 2);
  out.fy_px = k64.at<double>(1, 1);
  out.cy_px = k64.at<double>(1, 2);
  out.distortion.clear();
  if (!d.empty()) {
    if (d.rows != 1 && d.cols != 1) {
      throw ConfigError(source + ": distortion coefficients must be a 1xN or Nx1 matrix");
    }
    cv::Mat d64;
    d.convertTo(d64, CV_64F);
    d64 = d64.reshape(1, 1);
    for (int i = 0; i < d64.cols; ++i) {
      out.distortion.push_back(d64.at<double>(0, i));
    }
  }
}

// OpenCV's own YAML reader (cv::FileStorage, OpenCV 4.6) loops forever on some malformed files
// (found by fuzz_config), so calibration files, which come from outside, are read with yaml-cpp:
// the "%YAML:1.0" first line OpenCV writes is dropped, a matrix is a map {rows, cols, dt, data}
// (tag !!opencv-matrix).
CameraIntrinsics parse_opencv(const std::string& text, const std::string& source) {
  std::string body = text;
  if (body.rfind("%YAML:", 0) == 0) {
    const std::size_t eol = body.find('\n');
    body = eol == std::string::npos ? std::string() : body.substr(eol + 1);
  }
  // the project's strict reader: duplicate keys and bare .nan/.inf refused, naming the line
  const YAML::Node root = parse_yaml<ConfigError>(body, source);
  if (!root.IsMap()) {
    throw ConfigError(source + ": not a valid OpenCV YAML file (expected a map of named entries)");
  }
  // A camera matrix is 3x3, distortion at most 1x14: a larger side is refused before anything is
  // allocated, so no file can ask for gigabytes.
  constexpr int kMaxMatrixSide = 16;
  auto first_mat = [&root, &source](std::initializer_list<const char*> keys) {
    for (const char* key : keys) {
      const YAML::Node node = root[key];
      if (!node) {
        continue;
      }
      if (!node.IsMap()) {
        throw ConfigError(source + ": '" + key + "' is not an OpenCV matrix ({rows, cols, dt, data})");
      }
      int side[2] = {0, 0};
      const char* names[2] = {"rows", "cols"};
      for (int i = 0; i < 2; ++i) {
        const YAML::Node n = node[names[i]];
        int v = -1;
        if (n && n.IsScalar() && YAML::convert<int>::decode(n, v) && v >= 0 && v <= kMaxMatrixSide) {
          side[i] = v;
          continue;
        }
        throw ConfigError(source + ": '" + key + "." + names[i] + "' must be an integer in [0, " +
                          std::to_string(kMaxMatrixSide) + "]");
      }
      const YAML::Node data = node["data"];
      if (!data || !data.IsSequence()) {
        throw ConfigError(source + ": '" + key + "' has no 'data' list");
      }
      if (data.size() != static_cast<std::size_t>(side[0] * side[1])) {
        throw ConfigError(source + ": '" + key + "' declares " + std::to_string(side[0]) + "x" +
                          std::to_string(side[1]) + " but has " + std::to_string(data.size()) + " values");
      }
      cv::Mat m(side[0], side[1], CV_64F);
      for (int i = 0; i < side[0] * side[1]; ++i) {
        double v = 0.0;
        if (!data[static_cast<std::size_t>(i)].IsScalar() ||
            !YAML::convert<double>::decode(data[static_cast<std::size_t>(i)], v)) {
          throw ConfigError(source + ": '" + key + "' data[" + std::to_string(i) + "] is not a number");
        }
        m.at<double>(i / side[1], i % side[1]) = v;
      }
      return m;
    }
    return cv::Mat();
  };
  auto first_int = [&root](std::initializer_list<const char*> keys) {
    for (const char* key : keys) {
      const YAML::Node node = root[key];
      int v = 0;
      if (node && node.IsScalar() && YAML::convert<int>::decode(node, v)) {
        return v;
      }
    }
    return 0;
  };
  CameraIntrinsics out;
  fill_from_matrix(out, first_mat({"camera_matrix", "cameraMatrix", "K"}),
                   first_mat({"distortion_coefficients", "distCoeffs", "dist_coeffs", "D"}), source);
  out.width_px = first_int({"image_width", "imageWidth", "width"});
  out.height_px = first_int({"image_height", "imageHeight", "height"});
  return out;
}

std::vector<double> ros_matrix(const YAML::Node& root, const char* key, const std::string& source,
                               bool required) {
  const YAML::Node node = root[key];
  if (!node) {
    if (required) {
      throw ConfigError(source + ": missing '" + key + "' (ROS camera_info: {rows, cols, data})");
    }
    return {};
  }
  const YAML::Node data = node.IsMap() ? node["data"] : node;
  if (!data || !data.IsSequence()) {
    throw ConfigError(source + ": '" + key + "' has no 'data' list");
  }
  std::vector<double> values;
  for (const auto& v : data) {
    values.push_back(v.as<double>());
  }
  if (node.IsMap() && node["rows"] && node["cols"]) {
    const auto expected = node["rows"].as<std::size_t>() * node["cols"].as<std::size_t>();
    if (expected != values.size()) {
      throw ConfigError(source + ": '" + key + "' declares " + std::to_string(expected) +
                        " values but has " + std::to_string(values.size()));
    }
  }
  return values;
}

CameraIntrinsics parse_ros(const std::string& text, const std::string& source) {
  const YAML::Node root = parse_yaml<ConfigError>(text, source);
  if (!root.IsMap()) {
    throw ConfigError(source + ": expected a YAML map (ROS camera_info or OpenCV calibration)");
  }
  CameraIntrinsics out;
  try {
    const auto k = ros_matrix(root, "camera_matrix", source, true);
    if (k.size() != 9) {
      throw ConfigError(source + ": camera_matrix must have 9 values, has " +
                        std::to_string(k.size()));
    }
    cv::Mat kmat(3, 3, CV_64F);
    for (int i = 0; i < 9; ++i) {
      kmat.at<double>(i / 3, i % 3) = k[static_cast<std::size_t>(i)];
    }
    const auto d = ros_matrix(root, "distortion_coefficients", source, false);
    cv::Mat dmat = d.empty() ? cv::Mat() : cv::Mat(d, true).reshape(1, 1);
    fill_from_matrix(out, kmat, dmat, source);
    if (root["distortion_model"]) {
      const auto model = root["distortion_model"].as<std::string>();
      if (model != "plumb_bob" && model != "rational_polynomial" && model != "radtan") {
        throw ConfigError(source + ": distortion_model '" + model +
                          "' is not supported (use plumb_bob or rational_polynomial; "
                          "recalibrate fisheye/equidistant lenses with the pinhole model)");
      }
    }
    out.width_px = root["image_width"] ? root["image_width"].as<int>() : 0;
    out.height_px = root["image_height"] ? root["image_height"].as<int>() : 0;
  } catch (const YAML::Exception& e) {
    throw ConfigError(source + ": malformed camera_info value: " + e.what());
  }
  return out;
}

}  // namespace

cv::Matx33d CameraIntrinsics::camera_matrix() const {
  return {fx_px, skew, cx_px, 0.0, fy_px, cy_px, 0.0, 0.0, 1.0};
}

cv::Mat CameraIntrinsics::distortion_mat() const {
  if (distortion.empty()) {
    return {};
  }
  return cv::Mat(distortion, true).reshape(1, 1);
}

bool CameraIntrinsics::has_distortion() const {
  for (double d : distortion) {
    if (d != 0.0) {
      return true;
    }
  }
  return false;
}

void validate_intrinsics(const CameraIntrinsics& in, const std::string& source) {
  const std::string where = source + ": ";
  if (in.width_px <= 0 || in.height_px <= 0) {
    throw ConfigError(where + "image_width/image_height missing or not positive (" +
                      std::to_string(in.width_px) + "x" + std::to_string(in.height_px) +
                      "): the calibration must state the resolution it was made at");
  }
  if (in.width_px > kMaxCalibratedSidePx || in.height_px > kMaxCalibratedSidePx) {
    throw ConfigError(where + "image_width/image_height " + std::to_string(in.width_px) + "x" +
                      std::to_string(in.height_px) + " exceed " + std::to_string(kMaxCalibratedSidePx) +
                      " px: not a camera resolution");
  }
  for (double v : {in.fx_px, in.fy_px, in.cx_px, in.cy_px, in.skew}) {
    if (!finite(v)) {
      throw ConfigError(where + "camera matrix has a non-finite value");
    }
  }
  if (in.fx_px <= 0.0 || in.fy_px <= 0.0) {
    throw ConfigError(where + "focal lengths must be positive (fx=" + std::to_string(in.fx_px) +
                      ", fy=" + std::to_string(in.fy_px) + "): missing or zero calibration?");
  }
  const double aspect = in.fx_px / in.fy_px;
  if (aspect > kMaxAspect || aspect < 1.0 / kMaxAspect) {
    throw ConfigError(where + "fx/fy = " + std::to_string(aspect) +
                      " is implausible: check the camera matrix");
  }
  if (in.cx_px <= 0.0 || in.cx_px >= in.width_px || in.cy_px <= 0.0 ||
      in.cy_px >= in.height_px) {
    throw ConfigError(where + "principal point (" + std::to_string(in.cx_px) + ", " +
                      std::to_string(in.cy_px) + ") lies outside the " +
                      std::to_string(in.width_px) + "x" + std::to_string(in.height_px) +
                      " image: the calibration does not match the stated resolution");
  }
  const std::size_t n = in.distortion.size();
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14) {
    throw ConfigError(where + "distortion has " + std::to_string(n) +
                      " coefficients; OpenCV accepts 4, 5, 8, 12 or 14");
  }
  for (double d : in.distortion) {
    if (!finite(d)) {
      throw ConfigError(where + "distortion coefficient is not finite");
    }
  }
}

CameraIntrinsics parse_intrinsics(const std::string& text, const std::string& source) {
  CameraIntrinsics out = looks_like_opencv(text) ? parse_opencv(text, source) : parse_ros(text, source);
  validate_intrinsics(out, source);
  return out;
}

CameraIntrinsics load_intrinsics(const std::string& path) {
  return parse_intrinsics(read_text(path), path);
}

std::string to_ros_camera_info_yaml(const CameraIntrinsics& in, const std::string& camera_name) {
  std::ostringstream o;
  o << std::setprecision(17);
  o << "image_width: " << in.width_px << "\nimage_height: " << in.height_px
    << "\ncamera_name: " << camera_name << "\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: ["
    << in.fx_px << ", " << in.skew << ", " << in.cx_px << ", 0, " << in.fy_px << ", " << in.cy_px
    << ", 0, 0, 1]\ndistortion_model: "
    << (in.distortion.size() > 5 ? "rational_polynomial" : "plumb_bob")
    << "\ndistortion_coefficients:\n  rows: 1\n  cols: " << in.distortion.size() << "\n  data: [";
  for (std::size_t i = 0; i < in.distortion.size(); ++i) {
    o << (i ? ", " : "") << in.distortion[i];
  }
  o << "]\n";
  return o.str();
}

}  // namespace poise::camera
