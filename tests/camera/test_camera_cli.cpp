// `poise tags detect/render`, `poise camera`, `poise bench camera` through the real executable.
#include "poise/testing/testing.h"

#include <gtest/gtest.h>
// nlohmann's inlined accessors trip GCC's -Wnull-dereference at -O3 (a false positive in its header)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wnull-dereference"
#include <nlohmann/json.hpp>
#pragma GCC diagnostic pop

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

namespace poise::testing {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

constexpr double kCornerTolPx = 0.5;  // detected vs rendered truth, blur 0.8 px, noise 2

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("poise_camcli_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::vector<double> numbers_after(const std::string& text, const std::string& key) {
  std::vector<double> out;
  const auto pos = text.find(key);
  if (pos == std::string::npos) return out;
  const std::string rest = text.substr(pos + key.size(), 200);
  const std::regex number(R"(-?[0-9]+\.[0-9]+)");
  for (auto it = std::sregex_iterator(rest.begin(), rest.end(), number);
       it != std::sregex_iterator() && out.size() < 8; ++it) {
    out.push_back(std::stod(it->str()));
  }
  return out;
}

// GIVEN an image rendered by `poise tags render` with ids 3 and 8
// WHEN `poise tags detect --json` reads it
// THEN one record for the image holds both ids, corners within 0.5 px of the truth.
TEST(CameraCli, RenderThenDetectFindsTheTagsAtTheTrueCorners) {
  std::string line_of_output;
  const fs::path dir = fresh_dir("render");
  const std::string img = (dir / "two.png").string();
  const auto r = run({bin("poise"), "tags", "render", "-o", img, "--ids", "3,8", "--distance",
                      "0.9", "--yaw", "25", "--pitch", "-10"},
                     60s);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto d = run({bin("poise"), "tags", "detect", img, "--json"}, 60s);
  ASSERT_EQ(d.exit_code, 0) << d.output;
  // stdout: one record for the one image (stderr's summary line is not JSON)
  nlohmann::json record;
  for (std::istringstream lines(d.output); std::getline(lines, line_of_output);) {
    if (!line_of_output.empty() && line_of_output[0] == '{') {
      record = nlohmann::json::parse(line_of_output);
    }
  }
  ASSERT_EQ(record.value("image", ""), img) << d.output;
  ASSERT_EQ(record["detections"].size(), 2U) << d.output;
  for (int id : {3, 8}) {
    std::string line;
    nlohmann::json found;
    for (const auto& det : record["detections"]) {
      if (det["id"] == id) found = det;
    }
    ASSERT_FALSE(found.is_null()) << "id " << id << " not detected:\n" << d.output;
    EXPECT_EQ(found["hamming"], 0);
    EXPECT_TRUE(found.contains("decision_margin"));
    std::vector<double> corners;
    for (const auto& c : found["corners_px"]) {
      corners.push_back(c[0]);
      corners.push_back(c[1]);
    }
    // Truth printed by render: "<img>  id N  true corners (x, y) ..."
    std::istringstream rl(r.output);
    std::vector<double> truth;
    while (std::getline(rl, line)) {
      if (line.find("id " + std::to_string(id) + " ") != std::string::npos) {
        truth = numbers_after(line, "true corners");
      }
    }
    ASSERT_EQ(corners.size(), 8U) << found;
    ASSERT_EQ(truth.size(), 8U) << r.output;
    for (std::size_t i = 0; i < 8; ++i) {
      EXPECT_NEAR(corners[i], truth[i], kCornerTolPx) << "id " << id << " value " << i;
    }
  }
}

// Issue 20: --json gives one record per input: an image without tags is a record with an empty
// list, an unreadable one a record with its error.
TEST(CameraCli, JsonGivesOneRecordPerImageWithAnEmptyListWhenNoTagIsSeen) {
  const fs::path dir = fresh_dir("json");
  const std::string blank = (dir / "blank.pgm").string();
  std::ofstream(blank, std::ios::binary) << "P5\n64 48\n255\n" << std::string(64 * 48, '\x80');
  const std::string missing = (dir / "missing.png").string();
  const auto d = run({bin("poise"), "tags", "detect", blank, missing, "--json"}, 30s);
  EXPECT_EQ(d.exit_code, 1) << d.output;  // the unreadable image still fails the command
  std::vector<nlohmann::json> records;
  std::string line;
  for (std::istringstream lines(d.output); std::getline(lines, line);) {
    if (!line.empty() && line[0] == '{') records.push_back(nlohmann::json::parse(line));
  }
  ASSERT_EQ(records.size(), 2U) << d.output;
  EXPECT_EQ(records[0]["image"], blank);
  EXPECT_TRUE(records[0]["detections"].is_array());
  EXPECT_TRUE(records[0]["detections"].empty());
  EXPECT_EQ(records[0]["width_px"], 64);
  EXPECT_EQ(records[1]["image"], missing);
  EXPECT_TRUE(records[1]["detections"].is_null());
  EXPECT_TRUE(records[1].contains("error"));
}

TEST(CameraCli, UnreadableImagesAreReportedAndFailTheCommand) {
  const fs::path dir = fresh_dir("bad");
  std::ofstream(dir / "garbage.png") << "not an image";
  const auto d = run({bin("poise"), "tags", "detect", (dir / "garbage.png").string(),
                      (dir / "missing.png").string()},
                     30s);
  EXPECT_EQ(d.exit_code, 1) << d.output;
  EXPECT_NE(d.output.find("cannot read image '" + (dir / "garbage.png").string() + "'"),
            std::string::npos) << d.output;
  EXPECT_NE(d.output.find("missing.png"), std::string::npos) << d.output;
}

// Issue 19 item 5: images too small for the detector (libapriltag crashed on 2 px high) and
// files declaring huge sizes are refused and counted; the images after them are still detected.
TEST(CameraCli, GivenTinyAndHugeImagesBetweenGoodOnesWhenDetectedThenTheyAreRefusedAndTheRunGoesOn) {
  const fs::path dir = fresh_dir("limits");
  const std::string good = (dir / "good.png").string();
  ASSERT_EQ(run({bin("poise"), "tags", "render", "-o", good, "--ids", "3"}, 60s).exit_code, 0);
  const std::string tiny = (dir / "tiny.pgm").string();
  std::ofstream(tiny, std::ios::binary) << "P5\n640 2\n255\n" << std::string(1280, '\x80');
  const std::string huge = (dir / "huge.pgm").string();  // a 20-byte file declaring 30000 x 30000
  std::ofstream(huge, std::ios::binary) << "P5\n30000 30000\n255\n";
  const auto d = run({bin("poise"), "tags", "detect", tiny, huge, good}, 60s);
  EXPECT_EQ(d.exit_code, 1) << d.output;  // refused images fail the command, after the others ran
  EXPECT_NE(d.output.find("image '" + tiny + "' refused: pnm 640x2 px is below the"), std::string::npos) << d.output;
  EXPECT_NE(d.output.find("image '" + huge + "' refused: pnm 30000x30000 px exceeds"), std::string::npos) << d.output;
  EXPECT_NE(d.output.find(good + "  id 3"), std::string::npos) << d.output;
  EXPECT_NE(d.output.find("1 image(s), 1 detection(s), 2 unreadable or refused"), std::string::npos) << d.output;
  const auto small = run({bin("poise"), "tags", "detect", good, "--max-image-pixels", "1000"}, 60s);
  EXPECT_EQ(small.exit_code, 1) << small.output;
  EXPECT_NE(small.output.find("exceeds the maximum of 1000 pixels"), std::string::npos) << small.output;
}

TEST(CameraCli, MissingDeviceIsAClearError) {
  DomainLease domain;
  const auto r = run({bin("poise"), "camera", "--source", "/dev/video97", "--intrinsics",
                      source_path("config/camera/intrinsics_example_ros.yaml"), "--tags",
                      source_path("config/camera/tags_example.yaml"), "--domain",
                      std::to_string(domain.id())},
                     30s);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("/dev/video97 does not exist"), std::string::npos) << r.output;
}

TEST(CameraCli, BadIntrinsicsAreAClearError) {
  const fs::path dir = fresh_dir("intr");
  const std::string bad = (dir / "zero.yaml").string();
  std::ofstream(bad) << "image_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3, cols: 3, "
                        "data: [0, 0, 320, 0, 0, 240, 0, 0, 1]}\n";
  DomainLease domain;
  const auto r = run({bin("poise"), "camera", "--source", "synthetic", "--intrinsics", bad,
                      "--tags", source_path("config/camera/tags_example.yaml"), "--domain",
                      std::to_string(domain.id())},
                     30s);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("focal lengths must be positive"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(bad), std::string::npos) << r.output;
}

TEST(CameraCli, SyntheticRunEndsWithTheSource) {
  DomainLease domain;
  const auto r = run({bin("poise"), "camera", "--source", "synthetic:frames=4", "--fast",
                      "--intrinsics", source_path("config/camera/intrinsics_example_opencv.yaml"),
                      "--tags", source_path("config/camera/tags_example.yaml"), "--config",
                      source_path("config/camera/camera.yaml"), "--domain",
                      std::to_string(domain.id())},
                     60s);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("stopped after 4 frames, 4 poses published"), std::string::npos)
      << r.output;
}

// GIVEN a host file whose synthetic camera states a hostile corner noise (pixel_sigma_px)
// WHEN `poise run` loads it
// THEN it exits non-zero with a message naming the parameter, and no camera runs on it.
TEST(CameraCli, GivenAHostileSimCameraPixelSigmaWhenRunThenTheErrorNamesIt) {
  const fs::path dir = fresh_dir("sim_sigma");
  DomainLease domain;
  for (const char* value : {"-1", "0", "1e308", ".inf", ".nan", "fast"}) {
    const std::string host = (dir / "host.yaml").string();
    std::ofstream(host) << "components:\n  - {type: sim_camera, name: camera0, params: {pixel_sigma_px: " << value
                        << "}}\n";
    const auto r = run({bin("poise"), "run", host, "--domain", std::to_string(domain.id())}, 30s);
    EXPECT_NE(r.exit_code, 0) << value << ": " << r.output;
    EXPECT_NE(r.output.find("pixel_sigma_px"), std::string::npos) << value << ": " << r.output;
  }
}

TEST(CameraCli, HelpWorksEverywhere) {
  for (const auto& args : std::vector<std::vector<std::string>>{
           {"camera", "--help"}, {"tags", "--help"}, {"tags", "detect", "--help"},
           {"tags", "render", "--help"}, {"bench", "camera", "--help"}}) {
    std::vector<std::string> argv{bin("poise")};
    argv.insert(argv.end(), args.begin(), args.end());
    const auto r = run(argv, 30s);
    EXPECT_EQ(r.exit_code, 0) << args[0] << " " << args[1] << ": " << r.output;
  }
}

}  // namespace
}  // namespace poise::testing
