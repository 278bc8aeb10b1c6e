// End to end through a pseudo-terminal: PtyLink (device side) -> SerialPort/PortReader -> driver.
#include <gtest/gtest.h>

#include <unistd.h>
#include <termios.h>
#include <poll.h>
#include <fcntl.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "poise/imu/driver.h"
#include "poise/imu/faults.h"
#include "poise/imu/pty_link.h"
#include "poise/imu/serial_port.h"
#include "poise/testing/testing.h"

namespace poise::imu {
namespace {

using std::chrono::milliseconds;
constexpr auto kWait = milliseconds(10000);  // bound on every wait (CI machines are slow)
constexpr double kValueTol = 1e-5;           // 5 decimals on the wire

std::string temp_link(const std::string& tag) {
  return ::testing::TempDir() + "poise-imu-" + tag + "-" + std::to_string(::getpid());
}

RawSample sample(uint32_t seq) {
  RawSample s;
  s.seq = seq;
  s.t_us = 1000u + seq * 1000u;
  s.accel_mps2 = {0.001 * seq, 0.25, 9.8};
  s.gyro_rps = {0.01, -0.02, 0.001 * (seq % 100)};
  s.mag_ut = {22.0, 0.5 * (seq % 10), -41.0};
  return s;
}

/// Writes all of `data`, waiting for a reader and for buffer space (bounded).
bool write_all(PtyLink& link, const std::string& data) {
  return poise::testing::wait_until(
      [&] {
        const auto st = link.write(data);
        return st == PtyLink::WriteStatus::kWritten;
      },
      kWait);
}

/// Collects samples from a PortReader running in a thread.
class Harness {
 public:
  explicit Harness(const std::string& path)
      : driver_({}, {}, [this](const ImuSample& s, const SampleInfo&) {
          std::lock_guard<std::mutex> lock(mu_);
          samples_.push_back(s);
        }),
        reader_(ReaderOptions{path, SerialSettings{115200, 0.02, 0.1, "auto"}, 20}, driver_,
                [this](const std::string& m) {
                  std::lock_guard<std::mutex> lock(mu_);
                  log_.push_back(m);
                }) {
    thread_ = std::thread([this] { reader_.run([this] { return stop_.load(); }); });
  }
  ~Harness() { stop(); }
  void stop() {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
  }
  std::size_t count() {
    std::lock_guard<std::mutex> lock(mu_);
    return samples_.size();
  }
  std::vector<ImuSample> samples() {
    std::lock_guard<std::mutex> lock(mu_);
    return samples_;
  }
  std::string log() {
    std::lock_guard<std::mutex> lock(mu_);
    std::string s;
    for (const auto& l : log_) s += l + "\n";
    return s;
  }
  PortReader& reader() { return reader_; }
  const DriverStats& stats_after_stop() {
    stop();
    return driver_.stats();
  }

 private:
  std::mutex mu_;
  std::vector<ImuSample> samples_;
  std::vector<std::string> log_;
  ImuDriver driver_;
  PortReader reader_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

TEST(ImuPty, ValidAndCorruptLinesGiveExactlyTheValidSamplesAndCountsByReason) {
  // GIVEN a device streaming N lines through a fault injector (seeded), M of them corrupted
  const std::string path = temp_link("mixed");
  PtyLink link(path);
  Harness h(path);
  ASSERT_TRUE(poise::testing::wait_until([&] { return h.reader().connected(); }, kWait)) << h.log();
  FaultSpec spec = FaultSpec::parse("garbage=0.03,flip=0.03,truncate=0.03,dup=0.03,nan=0.03,seed=11");
  FaultInjector inj(spec);
  constexpr uint32_t kLines = 1000;
  std::vector<RawSample> sent_ok;
  for (uint32_t seq = 0; seq < kLines; ++seq) {
    const std::string line = format_imu_line(sample(seq));
    const auto before = inj.counts();
    const std::string bytes = inj.apply(line);
    const auto after = inj.counts();
    const bool lost = after[static_cast<std::size_t>(Fault::kFlip)] != before[static_cast<std::size_t>(Fault::kFlip)] ||
                      after[static_cast<std::size_t>(Fault::kTruncate)] != before[static_cast<std::size_t>(Fault::kTruncate)] ||
                      after[static_cast<std::size_t>(Fault::kNan)] != before[static_cast<std::size_t>(Fault::kNan)];
    if (!lost) sent_ok.push_back(sample(seq));
    if (!bytes.empty()) {
      ASSERT_TRUE(write_all(link, bytes)) << h.log();
    }
  }
  ASSERT_TRUE(write_all(link, "\r\n"));  // terminate a possibly truncated last line
  // THEN exactly the uncorrupted samples arrive, with their values
  const std::size_t n = sent_ok.size();
  EXPECT_TRUE(poise::testing::wait_until([&] { return h.count() >= n; }, kWait)) << h.count();
  poise::testing::sleep_ms(100);  // nothing more may come
  const auto got = h.samples();
  ASSERT_EQ(got.size(), n);
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(got[i].seq, sent_ok[i].seq);
    EXPECT_NEAR(got[i].accel_mps2.x(), sent_ok[i].accel_mps2.x(), kValueTol);
    EXPECT_NEAR(got[i].gyro_rps.z(), sent_ok[i].gyro_rps.z(), kValueTol);
    EXPECT_NEAR(got[i].mag_ut.y(), sent_ok[i].mag_ut.y(), kValueTol);
  }
  // AND every corrupted line is counted under its reason
  const auto& c = inj.counts();
  const DriverStats& st = h.stats_after_stop();
  const auto rej = [&st](RejectReason r) { return st.rejects[static_cast<std::size_t>(r)]; };
  const auto inj_n = [&c](Fault f) { return c[static_cast<std::size_t>(f)]; };
  std::cout << "injected: garbage " << inj_n(Fault::kGarbage) << ", flip " << inj_n(Fault::kFlip)
            << ", truncate " << inj_n(Fault::kTruncate) << ", dup " << inj_n(Fault::kDup) << ", nan "
            << inj_n(Fault::kNan) << "\n";
  EXPECT_GT(inj_n(Fault::kFlip), 0u);
  EXPECT_EQ(rej(RejectReason::kGarbage), inj_n(Fault::kGarbage));
  EXPECT_EQ(rej(RejectReason::kChecksumMismatch), inj_n(Fault::kFlip));
  EXPECT_EQ(rej(RejectReason::kTruncated), inj_n(Fault::kTruncate));
  EXPECT_EQ(rej(RejectReason::kDuplicateSeq), inj_n(Fault::kDup));
  EXPECT_EQ(rej(RejectReason::kNotFinite), inj_n(Fault::kNan));
  EXPECT_EQ(st.samples, n);
}

TEST(ImuPty, ResumesByItselfAfterTheDeviceDisappearsAndComesBack) {
  // GIVEN a reader connected to a device that streams 100 lines
  const std::string path = temp_link("reconnect");
  PtyLink link(path);
  Harness h(path);
  ASSERT_TRUE(poise::testing::wait_until([&] { return h.reader().connected(); }, kWait)) << h.log();
  for (uint32_t seq = 0; seq < 100; ++seq) ASSERT_TRUE(write_all(link, format_imu_line(sample(seq))));
  ASSERT_TRUE(poise::testing::wait_until([&] { return h.count() == 100; }, kWait)) << h.count();
  // WHEN the device is unplugged mid-line, stays away, and comes back (rebooted: seq from 0)
  ASSERT_TRUE(write_all(link, "$IMU,100,10"));
  poise::testing::sleep_ms(200);  // let the reader take the partial line (closing discards it)
  link.disconnect();
  ASSERT_TRUE(poise::testing::wait_until([&] { return !h.reader().connected(); }, kWait)) << h.log();
  poise::testing::sleep_ms(200);
  link.reconnect();
  ASSERT_TRUE(poise::testing::wait_until([&] { return h.reader().connects() == 2; }, kWait))
      << h.log();
  for (uint32_t seq = 0; seq < 100; ++seq) ASSERT_TRUE(write_all(link, format_imu_line(sample(seq))));
  // THEN publishing resumes without restarting the reader, stamps keep increasing
  ASSERT_TRUE(poise::testing::wait_until([&] { return h.count() == 200; }, kWait)) << h.log();
  const auto got = h.samples();
  for (std::size_t i = 1; i < got.size(); ++i) {
    ASSERT_GT(got[i].stamp_ns, got[i - 1].stamp_ns) << i;
  }
  const DriverStats& st = h.stats_after_stop();
  EXPECT_EQ(st.rejects[static_cast<std::size_t>(RejectReason::kTruncated)], 1u);
  EXPECT_EQ(st.disconnects, 1u);
  EXPECT_NE(h.log().find("lost"), std::string::npos) << h.log();
}

TEST(ImuSerialPort, OpenIsExclusive) {
  const std::string path = temp_link("excl");
  PtyLink link(path);
  SerialPort first(path, 115200);
  EXPECT_TRUE(first.is_pty());
  try {
    SerialPort second(path, 115200);
    FAIL() << "a second open must fail";
  } catch (const SerialError& e) {
    EXPECT_NE(std::string(e.what()).find("in use"), std::string::npos) << e.what();
  }
}

TEST(ImuSerialPort, ClearErrorsForMissingDeviceBadBaudAndNonTty) {
  try {
    SerialPort p("/nonexistent/ttyUSB9", 115200);
    FAIL();
  } catch (const SerialError& e) {
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
  try {
    SerialPort p("/dev/null", 12345);
    FAIL();
  } catch (const SerialError& e) {
    EXPECT_NE(std::string(e.what()).find("not supported"), std::string::npos) << e.what();
  }
  try {
    SerialPort p("/dev/null", 115200);
    FAIL();
  } catch (const SerialError& e) {
    EXPECT_NE(std::string(e.what()).find("not a serial device"), std::string::npos) << e.what();
  }
}

TEST(ImuPtyLink, RemovesItsSymlinkAndRefusesToReplaceAFile) {
  const std::string path = temp_link("link");
  {
    PtyLink link(path);
    EXPECT_EQ(::access(path.c_str(), F_OK), 0);
  }
  EXPECT_NE(::access(path.c_str(), F_OK), 0);
  const std::string file = temp_link("file");
  { FILE* f = std::fopen(file.c_str(), "w"); ASSERT_NE(f, nullptr); std::fclose(f); }
  EXPECT_THROW(PtyLink{file}, std::runtime_error);
  ::unlink(file.c_str());
}

// A simulated board whose own process stalled (a loaded host) writes its overdue lines in a burst;
// a real board never bursts, so the burst must wait for the reader, not be lost. Oracle: every
// line written arrives, counted by its newline; the burst is larger than the pty can hold (checked:
// without the wait the same burst is refused in part).
TEST(ImuPtyLink, GivenABurstLargerThanThePtyHoldsWhenTheReaderCatchesUpWithinTheWaitThenNoLineIsLost) {
  constexpr int kLines = 600;                              // ~60 kB, far over the pty's buffer
  constexpr auto kReaderStall = std::chrono::milliseconds(300);  // < kSimulatedBoardWaitMs
  const std::string path = temp_link("burst");
  PtyLink link(path);
  const int fd = ::open(path.c_str(), O_RDONLY | O_NOCTTY);
  ASSERT_GE(fd, 0);
  termios t{};
  ASSERT_EQ(::tcgetattr(fd, &t), 0);
  ::cfmakeraw(&t);
  ASSERT_EQ(::tcsetattr(fd, TCSANOW, &t), 0);
  auto burst = [&](int wait_ms) {
    int written = 0;
    for (int i = 0; i < kLines; ++i) {
      written += link.write(format_imu_line(sample(static_cast<uint32_t>(i))), wait_ms) == PtyLink::WriteStatus::kWritten;
    }
    return written;
  };
  auto drain = [&](int expect_lines) {
    int lines = 0;
    char buf[4096];
    const auto deadline = std::chrono::steady_clock::now() + kWait;
    while (lines < expect_lines && std::chrono::steady_clock::now() < deadline) {
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 100) <= 0) continue;
      const ssize_t n = ::read(fd, buf, sizeof buf);
      for (ssize_t k = 0; k < n; ++k) lines += buf[k] == '\n';
    }
    return lines;
  };
  // without a wait, a reader that is not reading refuses most of the burst (what was lost before)
  const int refused_without_wait = kLines - burst(0);
  EXPECT_GT(refused_without_wait, 0) << "the burst must exceed what the pty holds for this test to mean anything";
  (void)drain(kLines - refused_without_wait);
  // with the board's wait, the reader stalls 300 ms and then catches up: all of it arrives
  std::atomic<int> received{0};
  std::thread reader([&] {
    std::this_thread::sleep_for(kReaderStall);
    received = drain(kLines);
  });
  const int written = burst(kSimulatedBoardWaitMs);
  reader.join();
  EXPECT_EQ(written, kLines);
  EXPECT_EQ(received.load(), kLines);
  ::close(fd);
}

}  // namespace
}  // namespace poise::imu
