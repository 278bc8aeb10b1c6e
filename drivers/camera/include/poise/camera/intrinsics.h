// Camera intrinsics and lens distortion, loaded from YAML and validated at startup.
//
// Model: OpenCV pinhole + radial-tangential ("plumb_bob" / "rational_polynomial") distortion.
// Pixel coordinates: origin at the centre of the top-left pixel, x right, y down (OpenCV).
// Camera frame: x right, y down, z forward along the optical axis (OpenCV).
//
// Accepted files (format detected from the content):
//  - OpenCV calibration files written by cv::FileStorage (`%YAML:1.0`, `!!opencv-matrix`):
//    camera_matrix (or cameraMatrix / K), distortion_coefficients (or distCoeffs / D),
//    image_width, image_height.
//  - ROS camera_info YAML (camera_calibration_parsers): image_width, image_height,
//    camera_matrix {rows, cols, data}, distortion_model, distortion_coefficients {rows, cols, data}.
#pragma once

#include <opencv2/core.hpp>

#include <stdexcept>
#include <string>
#include <vector>

namespace poise::camera {

/// A startup failure in the camera configuration (intrinsics, tag map, config, source).
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct CameraIntrinsics {
  int width_px = 0;   ///< image width the calibration is valid for, px
  int height_px = 0;  ///< image height, px
  double fx_px = 0.0;  ///< focal length along x, px
  double fy_px = 0.0;  ///< focal length along y, px
  double cx_px = 0.0;  ///< principal point x, px
  double cy_px = 0.0;  ///< principal point y, px
  double skew = 0.0;   ///< K(0,1), px (0 for almost every camera)
  /// OpenCV order: k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]]; empty = no distortion.
  std::vector<double> distortion;

  /// 3x3 camera matrix K.
  [[nodiscard]] cv::Matx33d camera_matrix() const;
  /// Distortion as a 1xN CV_64F row (an empty Mat when there is none).
  [[nodiscard]] cv::Mat distortion_mat() const;
  [[nodiscard]] bool has_distortion() const;
};

/// Throws ConfigError naming the problem (missing, zero, non-finite or inconsistent values).
/// `source` names the file in the message.
void validate_intrinsics(const CameraIntrinsics& intrinsics, const std::string& source);

/// Loads and validates intrinsics from an OpenCV or ROS camera_info YAML file. Throws ConfigError.
CameraIntrinsics load_intrinsics(const std::string& path);

/// Parses intrinsics from YAML text (either format); `source` names it in errors. Throws ConfigError.
CameraIntrinsics parse_intrinsics(const std::string& text, const std::string& source);

/// Writes intrinsics as a ROS camera_info YAML text (used by tools and tests).
std::string to_ros_camera_info_yaml(const CameraIntrinsics& intrinsics,
                                    const std::string& camera_name = "camera");

}  // namespace poise::camera
