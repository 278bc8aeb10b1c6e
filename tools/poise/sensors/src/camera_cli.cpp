// `poise tags detect`, `poise tags render`, `poise bench camera` (no DDS).
#include "poise/camera/pipeline.h"
#include "poise/camera/renderer.h"
#include "poise/cli/common.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace poise::cli {
namespace {

using namespace poise::camera;

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

/// The default camera for tools that need one without a calibration: 640x480, f = 500 px.
CameraIntrinsics default_vga_camera() {
  CameraIntrinsics k;
  k.width_px = 640;
  k.height_px = 480;
  k.fx_px = 500.0;
  k.fy_px = 500.0;
  k.cx_px = 319.5;
  k.cy_px = 239.5;
  return k;
}

CameraIntrinsics scaled_camera(int width, int height) {
  CameraIntrinsics k;
  k.width_px = width;
  k.height_px = height;
  k.fx_px = 500.0 * width / 640.0;
  k.fy_px = k.fx_px;
  k.cx_px = (width - 1) / 2.0;
  k.cy_px = (height - 1) / 2.0;
  k.distortion = {-0.1, 0.03, 0.0, 0.0, 0.0};
  return k;
}

// ------------------------------------------------------------------ poise tags detect
struct DetectOptions {
  std::vector<std::string> files;
  std::string family = "tag36h11";
  bool json = false;
  double decimate = 1.0;  // full resolution: recall first
  double blur = 0.0;
  int threads = 1;
  int max_hamming = 2;
  bool refine_edges = true;
  int64_t max_image_pixels = ImageLimits{}.max_pixels;
};

void run_detect(const DetectOptions& o) {
  DetectorParams p;
  p.family = o.family;
  p.decimate = o.decimate;
  p.blur_sigma = o.blur;
  p.threads = o.threads;
  p.max_hamming = o.max_hamming;
  p.refine_edges = o.refine_edges;
  std::unique_ptr<TagDetector> detector;
  try {
    detector = std::make_unique<TagDetector>(p);
  } catch (const ConfigError& e) {
    throw Error(e.what());
  }
  std::vector<std::string> paths;
  for (const auto& f : o.files) {
    const auto expanded = expand_image_spec(f);
    if (expanded.empty()) {
      paths.push_back(f);  // reported as unreadable below
    }
    paths.insert(paths.end(), expanded.begin(), expanded.end());
  }
  int unreadable = 0;
  std::size_t total = 0;
  ImageLimits limits;
  limits.min_side_px = detector->min_image_side_px();
  limits.max_pixels = o.max_image_pixels;
  for (const auto& path : paths) {
    std::string error;
    const cv::Mat gray = read_gray_image(path, limits, error);
    // --json: one record per image, read or not (an image without tags is an empty list)
    nlohmann::ordered_json record = {{"image", path}, {"family", o.family}};
    const auto print_record = [&record] {
      // paths need not be UTF-8: invalid bytes become U+FFFD instead of throwing
      std::printf("%s\n", record.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
    };
    if (gray.empty()) {
      std::fprintf(stderr, "poise: error: %s\n", error.c_str());
      ++unreadable;
      if (o.json) {
        record["error"] = error;
        record["detections"] = nullptr;
        print_record();
      }
      continue;
    }
    const auto detections = detector->detect(gray);
    total += detections.size();
    if (o.json) {
      record["width_px"] = gray.cols;
      record["height_px"] = gray.rows;
      record["detections"] = nlohmann::ordered_json::array();
      for (const auto& d : detections) {
        nlohmann::ordered_json corners = nlohmann::ordered_json::array();
        for (const auto& c : d.corners_px) {
          corners.push_back({c.x(), c.y()});
        }
        record["detections"].push_back({{"id", d.id},
                                        {"hamming", d.hamming},
                                        {"decision_margin", d.decision_margin},
                                        {"corners_px", corners},
                                        {"center_px", {d.center_px.x(), d.center_px.y()}}});
      }
      print_record();
      continue;
    }
    for (const auto& d : detections) {
      {
        std::printf("%s  id %d  hamming %d  margin %.1f  corners (%.2f, %.2f) (%.2f, %.2f) "
                    "(%.2f, %.2f) (%.2f, %.2f)\n",
                    path.c_str(), d.id, d.hamming, d.decision_margin, d.corners_px[0].x(),
                    d.corners_px[0].y(), d.corners_px[1].x(), d.corners_px[1].y(),
                    d.corners_px[2].x(), d.corners_px[2].y(), d.corners_px[3].x(),
                    d.corners_px[3].y());
      }
    }
  }
  std::fflush(stdout);
  std::fprintf(stderr, "poise tags detect: %zu image(s), %zu detection(s), %d unreadable or refused\n",
               paths.size() - static_cast<std::size_t>(unreadable), total, unreadable);
  if (unreadable > 0) {
    throw ExitCode{1};
  }
}

// ------------------------------------------------------------------ poise tags render
struct RenderCliOptions {
  std::string out;
  std::string family = "tag36h11";
  std::vector<int> ids{0};
  double size_m = 0.16;
  double distance_m = 1.0;
  double yaw_deg = 20.0;
  double pitch_deg = 10.0;
  double noise = 2.0;
  double blur = 0.8;
  uint64_t seed = 1;
  std::string intrinsics;
};

void run_render(const RenderCliOptions& o) {
  try {
    const CameraIntrinsics k = o.intrinsics.empty() ? default_vga_camera() : load_intrinsics(o.intrinsics);
    SceneRenderer renderer(k, o.family, 3);
    // Camera at the origin looking north; tags in a row on a plane facing it.
    const Eigen::Isometry3d cam = look_at(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY());
    std::vector<SceneTag> tags;
    const double spacing = 1.6 * o.size_m;
    for (std::size_t i = 0; i < o.ids.size(); ++i) {
      SceneTag t;
      t.id = o.ids[i];
      t.size_m = o.size_m;
      const double x = (static_cast<double>(i) - 0.5 * static_cast<double>(o.ids.size() - 1)) * spacing;
      t.T_world_tag.linear() =
          (Eigen::AngleAxisd(o.yaw_deg * kDegToRad, Eigen::Vector3d::UnitZ()) *
           Eigen::AngleAxisd(kDegToRad * 90.0, Eigen::Vector3d::UnitX()) *
           Eigen::AngleAxisd(o.pitch_deg * kDegToRad, Eigen::Vector3d::UnitX()))
              .toRotationMatrix();
      t.T_world_tag.translation() =
          Eigen::Vector3d(0, o.distance_m, 0) + t.T_world_tag.linear().col(0) * x;
      tags.push_back(t);
    }
    RenderOptions ro;
    ro.noise_sigma = o.noise;
    ro.blur_sigma_px = o.blur;
    ro.seed = o.seed;
    const cv::Mat img = renderer.render(tags, cam, ro);
    if (!cv::imwrite(o.out, img)) {
      throw Error("cannot write '" + o.out + "' (directory exists? extension .png/.pgm/.jpg?)");
    }
    for (const auto& t : tags) {
      const auto c = renderer.project_corners(t, cam);
      std::printf("%s  id %d  true corners (%.2f, %.2f) (%.2f, %.2f) (%.2f, %.2f) (%.2f, %.2f)\n",
                  o.out.c_str(), t.id, c[0].x(), c[0].y(), c[1].x(), c[1].y(), c[2].x(), c[2].y(),
                  c[3].x(), c[3].y());
    }
  } catch (const ConfigError& e) {
    throw Error(e.what());
  } catch (const cv::Exception& e) {
    throw Error(std::string("cannot write '") + o.out + "': " + e.what());
  }
}

// ------------------------------------------------------------------ poise bench camera
struct BenchOptions {
  int frames = 12;
  int passes = 5;
  double decimate = DetectorParams{}.decimate;
  bool quick = false;
};

struct BenchRow {
  int width, height, threads;
  double bare_ms, pipeline_ms, bare_cpu_ms, pipeline_cpu_ms, pose_ms, detections_per_frame,
      world_ok_fraction;
};

double median(std::vector<double> v) {
  if (v.empty()) {
    return 0.0;
  }
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

double process_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

std::vector<cv::Mat> bench_frames(const CameraIntrinsics& k, const std::vector<SceneTag>& tags,
                                  int count) {
  SceneRenderer renderer(k, "tag36h11", 2);
  std::vector<cv::Mat> frames;
  for (int i = 0; i < count; ++i) {
    const double a = 0.35 * i;
    const Eigen::Vector3d eye(0.5 * std::sin(a), 0.0, 0.2 * std::cos(a));
    const Eigen::Isometry3d cam = look_at(eye, Eigen::Vector3d(0.0, 2.0, 0.0));
    RenderOptions ro;
    ro.noise_sigma = 2.0;
    ro.blur_sigma_px = 0.7;
    ro.seed = 1000 + static_cast<uint64_t>(i);
    frames.push_back(renderer.render(tags, cam, ro));
  }
  return frames;
}

void run_bench(const BenchOptions& o) {
  std::vector<SceneTag> tags;
  TagMap map;
  map.family = "tag36h11";
  for (int i = 0; i < 4; ++i) {
    SceneTag t;
    t.id = i;
    t.size_m = 0.16;
    t.T_world_tag.linear() =
        Eigen::AngleAxisd(90.0 * kDegToRad, Eigen::Vector3d::UnitX()).toRotationMatrix();
    t.T_world_tag.translation() = Eigen::Vector3d((i % 2) ? 0.3 : -0.3, 2.0, (i / 2) ? 0.25 : -0.25);
    tags.push_back(t);
    map.tags[i] = MappedTag{i, t.size_m, t.T_world_tag};
  }
  const int frames = o.quick ? 4 : o.frames;
  const int passes = o.quick ? 2 : o.passes;
  std::vector<BenchRow> rows;
  for (const auto& res : {std::pair<int, int>{640, 480}, std::pair<int, int>{1280, 720}}) {
    const CameraIntrinsics k = scaled_camera(res.first, res.second);
    std::fprintf(stderr, "bench camera: rendering %d frames at %dx%d...\n", frames, res.first,
                 res.second);
    const auto images = bench_frames(k, tags, frames);
    for (int threads : {1, 2}) {
      CameraConfig cfg;
      cfg.detector.threads = threads;
      cfg.detector.decimate = o.decimate;
      CameraPipeline pipeline(cfg, k, map);
      std::fprintf(stderr, "bench camera: %dx%d, %d thread(s), %d passes...\n", res.first,
                   res.second, threads, passes);
      double best_bare = std::numeric_limits<double>::infinity();
      double best_pipe = std::numeric_limits<double>::infinity();
      double best_bare_cpu = std::numeric_limits<double>::infinity();
      double best_pipe_cpu = std::numeric_limits<double>::infinity();
      std::vector<double> pose_ms;
      std::size_t detections = 0;
      std::size_t world_ok = 0;
      for (int pass = 0; pass < passes; ++pass) {
        // Alternate which runs first so load changes on a shared machine hit both alike.
        for (int which = 0; which < 2; ++which) {
          const bool bare = (which == 0) == (pass % 2 == 0);
          const auto t0 = std::chrono::steady_clock::now();
          const double c0 = process_cpu_ms();
          for (std::size_t i = 0; i < images.size(); ++i) {
            if (bare) {
              detections += pass == 0 ? pipeline.detector().detect(images[i]).size() : 0;
              if (pass != 0) {
                (void)pipeline.detector().detect(images[i]);
              }
            } else {
              Frame f;
              f.image = images[i];
              f.stamp_ns = static_cast<int64_t>(i);
              const FrameResult r = pipeline.process(f);
              world_ok += (pass == 0 && r.world.valid) ? 1 : 0;
              pose_ms.push_back(r.total_ms - r.detect_ms);
            }
          }
          const double ms = std::chrono::duration<double, std::milli>(
                                std::chrono::steady_clock::now() - t0)
                                .count() /
                            static_cast<double>(images.size());
          const double cpu = (process_cpu_ms() - c0) / static_cast<double>(images.size());
          (bare ? best_bare : best_pipe) = std::min(bare ? best_bare : best_pipe, ms);
          (bare ? best_bare_cpu : best_pipe_cpu) =
              std::min(bare ? best_bare_cpu : best_pipe_cpu, cpu);
        }
      }
      rows.push_back({res.first, res.second, threads, best_bare, best_pipe, best_bare_cpu,
                      best_pipe_cpu, median(pose_ms),
                      static_cast<double>(detections) / static_cast<double>(images.size()),
                      static_cast<double>(world_ok) / static_cast<double>(images.size())});
    }
  }
  std::printf("poise bench camera: tag36h11, 4 tags in view, decimate %.1f, refine_edges on, %d "
              "frames, best of %d passes; wall = elapsed, cpu = process CPU time (all threads)\n",
              o.decimate, frames, passes);
  std::printf("%-10s %3s %9s %8s %9s %8s %8s %8s %9s %10s %10s %6s\n", "resolution", "thr",
              "bare ms", "bare fps", "pipe ms", "pipe fps", "bare cpu", "pipe cpu", "pose ms",
              "ratio wall", "ratio cpu", "tags");
  for (const auto& r : rows) {
    char res[32];
    std::snprintf(res, sizeof res, "%dx%d", r.width, r.height);
    std::printf("%-10s %3d %9.2f %8.1f %9.2f %8.1f %8.2f %8.2f %9.3f %10.3f %10.3f %6.1f\n", res,
                r.threads, r.bare_ms, 1000.0 / r.bare_ms, r.pipeline_ms, 1000.0 / r.pipeline_ms,
                r.bare_cpu_ms, r.pipeline_cpu_ms, r.pose_ms, r.pipeline_ms / r.bare_ms,
                r.pipeline_cpu_ms / r.bare_cpu_ms, r.detections_per_frame);
  }
  std::printf("pose ms = median per-frame pipeline time after detection (undistort, IPPE per "
              "tag, joint LM, covariance); world pose valid on %.0f%% of frames\n",
              100.0 * rows.front().world_ok_fraction);
  std::printf("target: pipeline <= 1.1x bare detection\n");
}

}  // namespace

void register_camera_commands(CLI::App& app) {
  CLI::App* tags = subcommand_group(app, "tags", "AprilTag tools (detect, render)");

  auto d = std::make_shared<DetectOptions>();
  CLI::App* detect = tags->add_subcommand(
      "detect", "Detect AprilTags in images: image path, id, hamming, decision margin and the four "
                "corners (px, OpenCV convention: origin at the top-left pixel's centre) in "
                "libapriltag's order (bottom-left, bottom-right, top-right, top-left)");
  detect->add_option("files", d->files, "Image files, directories or quoted globs")->required();
  detect->add_option("--family", d->family, "Tag family")
      ->check(CLI::IsMember(tag_family_names()))
      ->capture_default_str();
  detect->add_flag("--json", d->json,
                   "JSON: one object per image and line: image, family, width_px, height_px, detections "
                   "[{id, hamming, decision_margin, corners_px, center_px}] (empty when no tag is seen; "
                   "null with an error for an unreadable image)");
  detect->add_option("--decimate", d->decimate, "Quad decimation (1 = full resolution, best recall)")
      ->check(CLI::Range(1.0, 8.0))
      ->capture_default_str();
  detect->add_option("--blur", d->blur, "Gaussian blur sigma before quad detection, px")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  detect->add_option("--threads", d->threads, "Detector threads")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  detect->add_option("--max-hamming", d->max_hamming, "Bit errors corrected (0-3)")
      ->check(CLI::Range(0, 3))
      ->capture_default_str();
  detect->add_option("--max-image-pixels", d->max_image_pixels,
                     "Largest image accepted (width x height, checked from the file header before decoding)")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 30))
      ->capture_default_str();
  detect->callback([d] { run_detect(*d); });

  auto r = std::make_shared<RenderCliOptions>();
  CLI::App* render = tags->add_subcommand(
      "render", "Render a synthetic camera image of tags (the family's own codes) and print their "
                "true corners; for testing detection without a camera");
  CLI::Option* render_out = add_output_file_option(render, &r->out, "the image (.png, .pgm, .jpg) (required)", false);
  require_one_of(render, {render_out, add_deprecated_alias(render, "--out", "-o/--output", &r->out)});
  render->add_option("--family", r->family, "Tag family")
      ->check(CLI::IsMember(tag_family_names()))
      ->capture_default_str();
  render->add_option("--ids", r->ids, "Tag ids, in a row")->delimiter(',')->capture_default_str();
  render->add_option("--size", r->size_m, "Tag size (detected square), m")
      ->check(CLI::Range(0.01, 5.0))
      ->capture_default_str();
  render->add_option("--distance", r->distance_m, "Distance from the camera, m")
      ->check(CLI::Range(0.05, 100.0))
      ->capture_default_str();
  render->add_option("--yaw", r->yaw_deg, "Tag yaw, deg")->capture_default_str();
  render->add_option("--pitch", r->pitch_deg, "Tag pitch, deg")->capture_default_str();
  render->add_option("--noise", r->noise, "Noise sigma, grey levels")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  render->add_option("--blur", r->blur, "Blur sigma, px")->check(CLI::Range(0.0, 20.0))->capture_default_str();
  render->add_option("--seed", r->seed, "Noise seed")->capture_default_str();
  render->add_option("--intrinsics", r->intrinsics,
                     "Camera intrinsics YAML (default: 640x480, f = 500 px, no distortion)");
  render->callback([r] { run_render(*r); });

  CLI::App* bench = subcommand_group(app, "bench", "Benchmarks (figures printed, not asserted)");
  auto b = std::make_shared<BenchOptions>();
  CLI::App* cam = bench->add_subcommand(
      "camera", "Camera pipeline throughput: frames/s and ms/frame at 640x480 and 1280x720, "
                "threads 1 and 2, full pipeline vs bare libapriltag detection on the same frames");
  cam->add_option("--frames", b->frames, "Distinct rendered frames per resolution")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cam->add_option("--passes", b->passes, "Timed passes (the fastest counts)")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  cam->add_option("--decimate", b->decimate, "Detector decimation")
      ->check(CLI::Range(1.0, 8.0))
      ->capture_default_str();
  cam->add_flag("--quick", b->quick, "4 frames, 2 passes (smoke test)");
  cam->callback([b] { run_bench(*b); });
}

}  // namespace poise::cli
