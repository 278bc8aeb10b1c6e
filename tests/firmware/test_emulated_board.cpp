// The GY-87 firmware's AVR binary (the ELF arduino-mk builds for the Uno) run on simavr with
// datasheet models of its sensors fed from a known motion; its UART is a pty that `poise imu`
// (a separate process) reads; this test subscribes to what the driver publishes over DDS.
// Oracle: for every published sample, the values the models held when the firmware read them
// (SI, body frame: the GY-87's chips share the body axes, config/drivers/imu.yaml), within the
// sensors' quantisation and the sketch's printed decimals.
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
#include <thread>

#include <poise/msg/diagnosticsPubSubTypes.h>
#include <poise/msg/imuPubSubTypes.h>

#include "poise/dds/participant.h"
#include "poise/firmware_emu/emulator.h"
#include "poise/testing/testing.h"

namespace poise::firmware_emu {
namespace {

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
double mag_lsb(MagVariant v) { return v == MagVariant::kQmc5883l ? kQmcLsb : kHmcLsb; }
double mag_tol(MagVariant v) { return 0.5 * mag_lsb(v) + 0.5e-2 + kFloatSlack; }

bool firmware_available(std::string* why) {
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
  }

  /// Starts `poise imu` and waits until it has the port open.
  void start_driver(bool wait_open = true) {
    driver_ = std::make_unique<Child>(std::vector<std::string>{
        poise::testing::bin("poise"), "imu", "--port", link_, "--domain", std::to_string(domain_.id()),
        "--status-period", "0.5"});
    if (wait_open) {
      ASSERT_TRUE(poise::testing::wait_until([&] { return emu_->has_reader(); }, 30s)) << driver_->output();
    }
  }
  Gy87Emulator& board() { return *emu_; }

  /// Waits until the driver has counted every line it was sent and published the last sample.
  void settle() {
    std::size_t delivered = 0;
    uint32_t last_seq = 0;
    for (const LineRecord& r : emu_->lines()) {
      if (r.delivered) {
        ++delivered;
        last_seq = r.seq;
      }
    }
    const bool ok = poise::testing::wait_until(
        [&] {
          std::lock_guard<std::mutex> lock(mu_);
          return counters_["samples"] + counters_["rejected_total"] >= delivered && samples_.count(last_seq) > 0;
        },
        15s);
    EXPECT_TRUE(ok) << "the driver did not count the " << delivered << " lines sent\n" << driver_->output();
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
  void expect_samples_equal_the_model(const std::string& what) {
    std::map<uint32_t, LineRecord> by_seq;
    std::size_t delivered = 0;
    for (const LineRecord& r : emu_->lines()) {
      if (!r.delivered) continue;
      ++delivered;
      by_seq[r.seq] = r;
    }
    const auto got = samples();
    ASSERT_FALSE(got.empty()) << driver_output();
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
    // Best-effort DDS on loopback loses nothing in practice; allow 1 %.
    EXPECT_GE(got.size() * 100, delivered * 99) << got.size() << " of " << delivered << " lines published";
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

std::size_t count_of(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

void run_variant(MagVariant variant) {
  // GIVEN a GY-87 with `variant` moving from power-on, `poise imu` reading its port
  EmulatorOptions o;
  o.mag = variant;
  Chain chain(o, to_string(variant));
  chain.start_driver();
  // WHEN the board runs for 3 s
  chain.board().run_for(3.0);
  chain.settle();
  // THEN every sample equals what the models held, the driver rejected nothing, and the firmware
  // broke no datasheet rule
  chain.expect_samples_equal_the_model(to_string(variant));
  EXPECT_EQ(chain.counter("rejected_total"), 0u) << chain.driver_output();
  EXPECT_EQ(chain.counter("samples_without_mag"), 0u);
  chain.expect_no_violations();
  std::printf("[ figures  ] %s: 3.0 s emulated in %.2f s; stack + heap peak %d B, static RAM %d B\n",
              to_string(variant), chain.board().host_seconds(), chain.board().stack_peak_bytes(),
              chain.board().static_ram_bytes());
}

TEST(EmulatedGy87, GivenAnHmc5883lBoardThenEverySampleThroughPoiseImuEqualsTheModelsWithinQuantisation) {
  REQUIRE_FIRMWARE();
  run_variant(MagVariant::kHmc5883l);
}

TEST(EmulatedGy87, GivenAQmc5883lCloneThenEverySampleThroughPoiseImuEqualsTheModelsWithinQuantisation) {
  REQUIRE_FIRMWARE();
  run_variant(MagVariant::kQmc5883l);
}

TEST(EmulatedGy87, GivenACrystal500PpmFastThenTheDriverMeasuresTheRateAndTheDriftOfTheEmulatedClock) {
  REQUIRE_FIRMWARE();
  // GIVEN a board whose clock runs 500 ppm fast against the host (the pacing of the emulation)
  constexpr double kCrystalPpm = 500.0;
  EmulatorOptions o;
  o.crystal_ppm = kCrystalPpm;
  Chain chain(o, "drift");
  chain.start_driver();
  // WHEN it streams for 12 s
  chain.board().run_for(12.0);
  const double drift = chain.metric("clock_drift");
  const double rate = chain.metric("rate");
  chain.settle();
  // THEN on its own clock the firmware samples every 10 ms exactly, its t_us is the emulated time
  // of the register read, and the driver measures the drift (host rate / sensor rate - 1) and
  // the host-clock rate that the 500 ppm imply
  const auto lines = chain.board().lines();
  ASSERT_GT(lines.size(), 1000u);
  double max_lag_us = 0;
  for (const LineRecord& r : lines) {
    const double lag_us = static_cast<double>(r.imu.t_ns) * 1e-3 - r.t_us;
    EXPECT_GE(lag_us, 0.0) << r.text;
    max_lag_us = std::max(max_lag_us, lag_us);
  }
  constexpr double kSampleInstantTolUs = 100.0;  // micros() just before the 0x3B pointer write
  EXPECT_LE(max_lag_us, kSampleInstantTolUs);
  const LineRecord& a = lines[lines.size() / 10];
  const LineRecord& b = lines.back();
  const double period_us = static_cast<double>(b.t_us - a.t_us) / static_cast<double>(b.seq - a.seq);
  EXPECT_NEAR(period_us, 10000.0, 1.0);
  const double expected_drift = (1.0 / (1.0 + kCrystalPpm * 1e-6) - 1.0) * 1e6;
  constexpr double kDriftTolPpm = 30.0;  // the driver's own clock test (ImuClockSync) tolerance
  EXPECT_NEAR(drift, expected_drift, kDriftTolPpm) << chain.driver_output();
  constexpr double kRateTolHz = 0.05;
  EXPECT_NEAR(rate, 100.0 * (1.0 + kCrystalPpm * 1e-6), kRateTolHz);
  std::printf("[ figures  ] crystal +%.0f ppm: driver drift %.1f ppm (expected %.1f), rate %.4f Hz "
              "(expected %.4f), sensor period %.3f us, t_us before the register read by <= %.1f us\n",
              kCrystalPpm, drift, expected_drift, rate, 100.0 * (1.0 + kCrystalPpm * 1e-6), period_us,
              max_lag_us);
  chain.expect_samples_equal_the_model("drift");
}

TEST(EmulatedGy87, GivenNoMagnetometerOrAnUnknownOneAt0x2CThenTheFirmwareSaysSoAndTheDriverPublishesWithoutMag) {
  REQUIRE_FIRMWARE();
  for (const MagVariant v : {MagVariant::kNone, MagVariant::kUnknownAt0x2C}) {
    SCOPED_TRACE(to_string(v));
    // GIVEN a board without a magnetometer the firmware knows
    EmulatorOptions o;
    o.mag = v;
    Chain chain(o, to_string(v));
    chain.start_driver();
    // WHEN it runs for 1.5 s
    chain.board().run_for(1.5);
    chain.settle();
    // THEN the firmware warns once and sends empty mag fields; the driver publishes every sample
    // with valid.mag = false and counts them
    const std::string text = chain.board().uart_text();
    EXPECT_EQ(count_of(text, "# warning: no magnetometer"), 1u) << text.substr(0, 400);
    chain.expect_samples_equal_the_model(to_string(v));
    EXPECT_EQ(chain.counter("samples_without_mag"), chain.counter("samples"));
    EXPECT_GT(chain.counter("samples"), 100u);
    EXPECT_EQ(chain.counter("rejected_total"), 0u);
    chain.expect_no_violations();
    std::printf("[ figures  ] %s: firmware: \"# warning: no magnetometer ...\"; driver: samples %lu, "
                "samples_without_mag %lu, info_lines %lu\n",
                to_string(v), static_cast<unsigned long>(chain.counter("samples")),
                static_cast<unsigned long>(chain.counter("samples_without_mag")),
                static_cast<unsigned long>(chain.counter("info_lines")));
  }
}

TEST(EmulatedGy87, GivenSensorsThatStopAnsweringMidRunThenTheFirmwareSaysSoAndTheDriverCountsTheGaps) {
  REQUIRE_FIRMWARE();
  // GIVEN the MPU6050, the HMC5883L and the BMP180 each NACKing their address for 0.3 s
  EmulatorOptions o;
  o.nack_windows = {{"MPU6050", 1.0, 1.3}, {"HMC5883L", 1.6, 1.9}, {"BMP180", 2.2, 2.5}};
  Chain chain(o, "nack");
  chain.start_driver();
  // WHEN the board runs for 3.2 s
  chain.board().run_for(3.2);
  chain.settle();
  // THEN the firmware reports each: an error line per lost MPU6050 sample (seq still counts),
  // and empty mag / pressure fields (never the stale values) until the sensor answers again
  const std::string text = chain.board().uart_text();
  const std::size_t mpu_errors = count_of(text, "# error: MPU6050 read failed");
  EXPECT_EQ(mpu_errors, chain.board().nacks("MPU6050"));
  EXPECT_NEAR(static_cast<double>(mpu_errors), 30.0, 1.0);  // 0.3 s at 100 Hz
  EXPECT_EQ(count_of(text, "# error: magnetometer not answering"), 1u);
  EXPECT_EQ(count_of(text, "# error: BMP180 not answering"), 1u);
  chain.expect_samples_equal_the_model("nack");
  // AND the driver counts the lost MPU6050 samples as a seq gap and the mag-less samples
  std::size_t without_mag = 0, without_p = 0;
  for (const LineRecord& r : chain.board().lines()) {
    without_mag += r.has_mag ? 0 : 1;
    without_p += r.has_pressure ? 0 : 1;
  }
  EXPECT_EQ(chain.counter("dropped_seq_gap"), mpu_errors);
  EXPECT_EQ(chain.counter("samples_without_mag"), without_mag);
  EXPECT_EQ(chain.counter("rejected_total"), 0u);
  EXPECT_GE(chain.counter("info_lines"), mpu_errors + 2);
  chain.expect_no_violations();
  std::printf("[ figures  ] NACK windows 0.3 s each: firmware sent %zu MPU6050 error lines, one mag and "
              "one BMP180 error line; driver: dropped_seq_gap %lu, samples_without_mag %lu, "
              "%zu samples without pressure, info_lines %lu, rejected_total %lu\n",
              mpu_errors, static_cast<unsigned long>(chain.counter("dropped_seq_gap")),
              static_cast<unsigned long>(chain.counter("samples_without_mag")), without_p,
              static_cast<unsigned long>(chain.counter("info_lines")),
              static_cast<unsigned long>(chain.counter("rejected_total")));
}

TEST(EmulatedGy87, GivenPowerOnWhileMovingThenTheFirstSampleAlreadyCarriesTheMotion) {
  REQUIRE_FIRMWARE();
  // GIVEN a board rotating and accelerating from the instant it is powered, the port open
  EmulatorOptions o;
  o.scenario = "moving";
  o.seed = 7;
  Chain chain(o, "moving");
  chain.start_driver();
  // WHEN it runs for 1 s
  chain.board().run_for(1.0);
  chain.settle();
  // THEN no sensor was read before it was ready (gyro start-up, first magnetometer measurement),
  // and the first sample the driver publishes (seq 0) is the motion at that instant
  chain.expect_no_violations();
  const auto got = chain.samples();
  ASSERT_EQ(got.count(0u), 1u) << chain.driver_output();
  const auto& first = got.at(0u);
  const double rate = std::hypot(first.gyro_rps().x(), first.gyro_rps().y(), first.gyro_rps().z());
  EXPECT_GT(rate, 0.05) << "the board is turning";
  EXPECT_TRUE(first.valid().mag());
  chain.expect_samples_equal_the_model("moving from power-on");
  const auto lines = chain.board().lines();
  ASSERT_FALSE(lines.empty());
  std::printf("[ figures  ] moving from power-on: first sample at %.1f ms after power-on, |gyro| %.3f rad/s\n",
              static_cast<double>(lines.front().imu.t_ns) * 1e-6, rate);
}

void run_open_while_streaming(bool reset_on_open) {
  // GIVEN a board streaming for 1 s with nobody reading its port
  EmulatorOptions o;
  o.reset_on_open = reset_on_open;
  Chain chain(o, reset_on_open ? "open-reset" : "open-noreset");
  std::thread board([&] { chain.board().run_for(3.0); });
  poise::testing::sleep_ms(1000);
  // WHEN `poise imu` opens it
  chain.start_driver(false);
  board.join();
  chain.settle();
  const auto lines = chain.board().lines();
  const auto got = chain.samples();
  ASSERT_FALSE(got.empty()) << chain.driver_output();
  const std::string text = chain.board().uart_text();
  if (reset_on_open) {
    // THEN an Uno resets (DTR): the firmware starts again (banner, seq from 0) with the sensors
    // still configured from before, and the driver sees a clean start
    EXPECT_EQ(chain.board().boots(), 1);
    EXPECT_EQ(count_of(text, "# gy87_poise v1 ready"), 2u);
    EXPECT_EQ(got.begin()->first, 0u);
    EXPECT_GE(chain.counter("info_lines"), 2u);
    EXPECT_EQ(chain.counter("rejected_total"), 0u);
  } else {
    // THEN a board without the auto-reset is joined mid-stream: at most the cut line is lost
    // (counted as garbage or truncated), the rest is published from the seq it had reached
    EXPECT_EQ(chain.board().boots(), 0);
    EXPECT_GT(got.begin()->first, 50u);
    EXPECT_LE(chain.counter("rejected_total"), 1u);
    EXPECT_EQ(chain.counter("info_lines"), 0u);
  }
  chain.expect_samples_equal_the_model(reset_on_open ? "opened, Uno reset" : "opened, no reset");
  chain.expect_no_violations();
  std::printf("[ figures  ] port opened after 1 s (%s): first published seq %u, driver rejected_total %lu "
              "(garbage %lu, truncated %lu), info_lines %lu, sensor_restarts %lu\n",
              reset_on_open ? "Uno auto-reset" : "no reset", got.begin()->first,
              static_cast<unsigned long>(chain.counter("rejected_total")),
              static_cast<unsigned long>(chain.counter("rejected_garbage")),
              static_cast<unsigned long>(chain.counter("rejected_truncated")),
              static_cast<unsigned long>(chain.counter("info_lines")),
              static_cast<unsigned long>(chain.counter("sensor_restarts")));
}

TEST(EmulatedGy87, GivenTheBoardStreamingWhenAnUnoIsOpenedThenItRestartsAndTheDriverSeesACleanStart) {
  REQUIRE_FIRMWARE();
  run_open_while_streaming(true);
}

TEST(EmulatedGy87, GivenTheBoardStreamingWhenABoardWithoutAutoResetIsOpenedThenTheDriverJoinsMidStream) {
  REQUIRE_FIRMWARE();
  run_open_while_streaming(false);
}

}  // namespace
}  // namespace poise::firmware_emu
