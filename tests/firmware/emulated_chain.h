// The emulated GY-87 chain of the firmware tests: the board (Gy87Emulator), `poise imu` on its
// pty as a child process, and a DDS subscriber to what the driver publishes; the tolerances and
// the comparison of every published sample with the models' values. Test code only.
#pragma once

#include <gtest/gtest.h>

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include "poise/dds/participant.h"
#include "poise/firmware_emu/emulator.h"
#include "poise/testing/testing.h"

namespace poise::firmware_emu::test_chain {


using namespace std::chrono_literals;
using poise::testing::Child;

constexpr double kPi = 3.14159265358979323846;
// One count of each sensor as the sketch configures it, and the sketch's printed decimals
// (accel 3, gyro 4, mag 2, temperature 2). A reported value may differ from the model's by half
// a count (the part rounds) plus half the last printed digit, plus float32 rounding on the AVR.
constexpr double kAccelLsb = 9.80665 / 8192.0;         // m/s^2, +-4 g
constexpr double kGyroLsb = 1.0 / 65.5 * kPi / 180.0;  // rad/s, +-500 deg/s
constexpr double kHmcLsb = 100.0 / 1090.0;             // uT, gain 1090 LSB/Ga
constexpr double kQmcLsb = 100.0 / 12000.0;            // uT, 2 G range
constexpr double kTempLsb = 1.0 / 340.0;               // C
constexpr double kFloatSlack = 1e-5;
constexpr double kAccelTol = 0.5 * kAccelLsb + 0.5e-3 + kFloatSlack;
constexpr double kGyroTol = 0.5 * kGyroLsb + 0.5e-4 + kFloatSlack;
constexpr double kTempTol = 0.5 * kTempLsb + 0.5e-2 + kFloatSlack;
// The BMP180's compensated pressure comes in whole Pa, one UP count apart (1 or 2 Pa at oss 1,
// Bmp180Model test): the model picks the UP nearest the truth, so half a step.
constexpr double kPressureTolPa = 1.0;
inline double mag_lsb(MagVariant v) { return v == MagVariant::kQmc5883l ? kQmcLsb : kHmcLsb; }
inline double mag_tol(MagVariant v) { return 0.5 * mag_lsb(v) + 0.5e-2 + kFloatSlack; }

inline bool firmware_available(std::string* why) {
  if (!POISE_FIRMWARE_TOOLS) {
    *why = "arduino-mk / gcc-avr not installed (tools/setup.sh installs them)";
    return false;
  }
  if (::access(POISE_GY87_ELF, R_OK) != 0) {
    *why = std::string("firmware not built: ") + POISE_GY87_ELF;
    return false;
  }
  return true;
}

#define REQUIRE_FIRMWARE()                        \
  do {                                            \
    std::string why_;                             \
    if (!firmware_available(&why_)) POISE_SKIP(why_); \
  } while (0)

/// The emulated board, `poise imu` on its pty and a DDS subscriber to the driver's topics.
class Chain {
 public:
  explicit Chain(EmulatorOptions options, const std::string& tag)
      : link_(::testing::TempDir() + "poise-gy87-" + tag + "-" + std::to_string(::getpid())),
        participant_({domain_.id(), "", "", "gy87 emulation test"}),
        diag_(participant_, "diagnostics",
              [this](const msg::FilterDiagnostics& m, const auto&) {
                if (m.component_name().to_string() != "imu_driver") return;
                std::lock_guard<std::mutex> lock(mu_);
                for (const auto& c : m.counters()) counters_[c.name().to_string()] = c.value();
                for (const auto& x : m.metrics()) metrics_[x.name().to_string()] = x.value();
              }),
        imu_(participant_, "imu", [this](const msg::ImuSample& m, const auto&) {
          std::lock_guard<std::mutex> lock(mu_);
          samples_[m.header().seq()] = m;
          if (first_seq_ < 0) first_seq_ = m.header().seq();
        }) {
    options.link = link_;
    options.elf = POISE_GY87_ELF;
    variant_ = options.mag;
    emu_ = std::make_unique<Gy87Emulator>(options);
  }
  ~Chain() {
    if (driver_) driver_->signal(SIGKILL);
    if (!config_.empty()) ::unlink(config_.c_str());
  }

  /// Starts `poise imu` and waits until it has the port open.
  /// `config_yaml`: the driver's YAML (written to a file for --config), empty for the defaults.
  void start_driver(bool wait_open = true, const std::string& config_yaml = "") {
    std::vector<std::string> argv{poise::testing::bin("poise"), "imu", "--port", link_, "--domain",
                                  std::to_string(domain_.id()), "--status-period", "0.5"};
    if (!config_yaml.empty()) {
      config_ = link_ + ".yaml";
      std::FILE* f = std::fopen(config_.c_str(), "w");
      ASSERT_NE(f, nullptr) << config_;
      std::fputs(config_yaml.c_str(), f);
      std::fclose(f);
      argv.insert(argv.end(), {"--config", config_});
    }
    driver_ = std::make_unique<Child>(argv);
    if (wait_open) {
      // The port open and the driver's writers matched to this test's readers (best-effort
      // samples published before the match would be lost).
      ASSERT_TRUE(poise::testing::wait_until([&] { return emu_->has_reader(); }, 30s)) << driver_->output();
      ASSERT_TRUE(imu_.wait_for_writers(1, 30s)) << driver_->output();
      ASSERT_TRUE(diag_.wait_for_writers(1, 30s)) << driver_->output();
    }
  }
  Gy87Emulator& board() { return *emu_; }

  /// Lines the firmware sent that reached the pty whole.
  std::size_t delivered_lines() const {
    std::size_t n = 0;
    for (const LineRecord& r : emu_->lines()) n += r.delivered ? 1 : 0;
    return n;
  }

  /// Waits until the driver has counted every line it was sent and published every sample, then
  /// stops it.
  void settle() {
    const std::size_t delivered = delivered_lines();
    const bool ok = poise::testing::wait_until(
        [&] {
          std::lock_guard<std::mutex> lock(mu_);
          return counters_["samples"] + counters_["rejected_total"] >= delivered &&
                 counters_["published"] >= counters_["samples"];
        },
        40s);
    EXPECT_TRUE(ok) << "the driver did not count the " << delivered << " lines sent\n" << driver_->output();
    poise::testing::sleep_ms(300);  // the last samples on their way through DDS
    driver_->signal(SIGINT);
    const auto code = driver_->wait_for(15s);
    EXPECT_TRUE(code.has_value() && *code == 0) << driver_->output();
  }

  uint64_t counter(const std::string& k) {
    std::lock_guard<std::mutex> lock(mu_);
    return counters_[k];
  }
  double metric(const std::string& k) {
    std::lock_guard<std::mutex> lock(mu_);
    return metrics_.count(k) > 0 ? metrics_[k] : std::nan("");
  }
  std::map<uint32_t, msg::ImuSample> samples() {
    std::lock_guard<std::mutex> lock(mu_);
    return samples_;
  }
  std::string driver_output() const { return driver_ ? driver_->output() : ""; }

  /// Every published sample against the line the firmware sent with that seq (the latest boot's).
  /// Returns the largest errors in counts; prints them.
  /// `from_first_received`: completeness counted from the first sample this test received (the
  /// driver started before the test's reader was matched).
  void expect_samples_equal_the_model(const std::string& what, bool from_first_received = false) {
    const auto got = samples();
    ASSERT_FALSE(got.empty()) << driver_output();
    std::map<uint32_t, LineRecord> by_seq;
    std::size_t delivered = 0;
    bool counting = !from_first_received;
    for (const LineRecord& r : emu_->lines()) {
      if (!r.delivered) continue;
      if (r.seq == got.begin()->first) counting = true;
      delivered += counting ? 1 : 0;
      by_seq[r.seq] = r;
    }
    double e_acc = 0, e_gyr = 0, e_mag = 0, e_p = 0, e_t = 0;
    std::size_t with_mag = 0, with_p = 0;
    for (const auto& [seq, m] : got) {
      const auto it = by_seq.find(seq);
      ASSERT_NE(it, by_seq.end()) << "published seq " << seq << " was never sent";
      const LineRecord& r = it->second;
      ASSERT_TRUE(r.imu.valid) << r.text;
      const MotionSample& v = r.imu.values;
      const Eigen::Vector3d acc(m.accel_mps2().x(), m.accel_mps2().y(), m.accel_mps2().z());
      const Eigen::Vector3d gyr(m.gyro_rps().x(), m.gyro_rps().y(), m.gyro_rps().z());
      const double ea = (acc - v.accel_mps2).cwiseAbs().maxCoeff();
      const double eg = (gyr - v.gyro_rps).cwiseAbs().maxCoeff();
      EXPECT_LE(ea, kAccelTol) << "seq " << seq << " " << r.text << "\nmodel " << v.accel_mps2.transpose();
      EXPECT_LE(eg, kGyroTol) << "seq " << seq << " " << r.text << "\nmodel " << v.gyro_rps.transpose();
      e_acc = std::max(e_acc, ea);
      e_gyr = std::max(e_gyr, eg);
      ASSERT_TRUE(m.valid().temperature());
      const double et = std::abs(m.temperature_c() - v.temperature_c);
      EXPECT_LE(et, kTempTol) << "seq " << seq << " " << r.text;
      e_t = std::max(e_t, et);
      EXPECT_EQ(m.valid().mag(), r.has_mag) << "seq " << seq << " " << r.text;
      if (m.valid().mag() && r.has_mag) {
        ++with_mag;
        const Eigen::Vector3d mag(m.mag_ut().x(), m.mag_ut().y(), m.mag_ut().z());
        const double em = (mag - r.mag.values.mag_ut).cwiseAbs().maxCoeff();
        EXPECT_LE(em, mag_tol(variant_)) << "seq " << seq << " " << r.text << "\nmodel "
                                          << r.mag.values.mag_ut.transpose();
        e_mag = std::max(e_mag, em);
      }
      EXPECT_EQ(m.valid().pressure(), r.has_pressure) << "seq " << seq << " " << r.text;
      if (m.valid().pressure() && r.has_pressure) {
        ++with_p;
        const double ep = std::abs(m.pressure_pa() - r.pressure.values.pressure_pa);
        EXPECT_LE(ep, kPressureTolPa) << "seq " << seq << " " << r.text;
        e_p = std::max(e_p, ep);
      }
    }
    // That every line reached the driver is its counters' part (the tests); here every sample
    // received is checked. `imu` is best-effort: on an idle machine none was lost in the runs
    // measured, on one loaded by other builds (load 6 on 2 cores) some were; 80 % must arrive.
    EXPECT_GE(got.size() * 100, delivered * 80) << got.size() << " of " << delivered << " lines published";
    std::printf("[ figures  ] %s: %zu lines sent, %zu samples received (%zu with mag, %zu with pressure); "
                "max |error| accel %.2f counts, gyro %.2f, mag %.2f, temperature %.2f, pressure %.2f Pa\n",
                what.c_str(), delivered, got.size(), with_mag, with_p, e_acc / kAccelLsb, e_gyr / kGyroLsb,
                e_mag / mag_lsb(variant_), e_t / kTempLsb, e_p);
  }

  void expect_no_violations() {
    for (const Violation& v : emu_->violations()) {
      ADD_FAILURE() << v.device << " at " << v.t_ns * 1e-6 << " ms: " << v.rule;
    }
  }

 private:
  poise::testing::DomainLease domain_;
  std::string link_;
  std::string config_;
  dds::Participant participant_;
  std::mutex mu_;
  std::map<std::string, uint64_t> counters_;
  std::map<std::string, double> metrics_;
  std::map<uint32_t, msg::ImuSample> samples_;
  int64_t first_seq_ = -1;
  dds::Reader<msg::FilterDiagnosticsPubSubType> diag_;
  dds::Reader<msg::ImuSamplePubSubType> imu_;
  std::unique_ptr<Gy87Emulator> emu_;
  std::unique_ptr<Child> driver_;
  MagVariant variant_ = MagVariant::kHmc5883l;
};

inline std::size_t count_of(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

}  // namespace poise::firmware_emu::test_chain
