// I2C slave models for the emulated GY-87 (tests/firmware): the bus hands each condition the
// AVR's TWI master puts on the wire (start + address, data bytes, stop) to the addressed device.
// A device that is absent, unreachable (behind the MPU6050's auxiliary bus with bypass off) or
// inside a NACK window does not acknowledge its address, as a real part would not.
//
// Datasheet rules the firmware breaks are recorded as violations; the model keeps answering the
// way the part would (stale or zero data), so a firmware mistake shows both as a violation and
// as a wrong value downstream.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace poise::firmware_emu {

/// One datasheet rule the firmware broke, at emulated time t_ns (since power-on).
struct Violation {
  int64_t t_ns = 0;
  std::string device;
  std::string rule;
};

class I2cDevice {
 public:
  I2cDevice(std::string name, uint8_t address) : name_(std::move(name)), address_(address) {}
  virtual ~I2cDevice() = default;
  I2cDevice(const I2cDevice&) = delete;
  I2cDevice& operator=(const I2cDevice&) = delete;

  [[nodiscard]] const std::string& name() const { return name_; }
  [[nodiscard]] uint8_t address() const { return address_; }
  /// The device does not acknowledge its address from `from_ns` until `to_ns` (a loose wire).
  void add_nack_window(int64_t from_ns, int64_t to_ns) { nack_windows_.emplace_back(from_ns, to_ns); }
  /// Whether the device acknowledges its address at t_ns (counts a NACK when it does not).
  bool acknowledge(int64_t t_ns);
  [[nodiscard]] uint64_t nacks() const { return nacks_; }
  [[nodiscard]] int64_t last_nack_ns() const { return last_nack_ns_; }
  [[nodiscard]] const std::vector<Violation>& violations() const { return violations_; }

  // One transaction: start(read) after the address was acknowledged, then write()s or read()s,
  // then stop() (a stop condition or a repeated start).
  virtual void start(bool read, int64_t t_ns) = 0;
  virtual bool write(uint8_t byte, int64_t t_ns) = 0;  ///< true: ACK
  virtual uint8_t read(int64_t t_ns) = 0;
  virtual void stop(int64_t t_ns) = 0;

 protected:
  /// False while the device cannot be reached at all (e.g. behind a closed bypass switch).
  [[nodiscard]] virtual bool reachable() const { return true; }
  void violate(int64_t t_ns, std::string rule);

 private:
  std::string name_;
  uint8_t address_;
  std::vector<std::pair<int64_t, int64_t>> nack_windows_;
  uint64_t nacks_ = 0;
  int64_t last_nack_ns_ = -1;
  std::vector<Violation> violations_;
};

/// A register-file device: the first byte written after SLA+W is the register pointer, further
/// bytes are written to registers; reads return registers; the pointer advances after each byte
/// (next_pointer(): the part's own auto-increment rule).
class RegisterDevice : public I2cDevice {
 public:
  using I2cDevice::I2cDevice;
  void start(bool read, int64_t t_ns) override;
  bool write(uint8_t byte, int64_t t_ns) override;
  uint8_t read(int64_t t_ns) override;
  void stop(int64_t t_ns) override;

 protected:
  virtual void on_write(uint8_t reg, uint8_t value, int64_t t_ns) = 0;
  virtual uint8_t on_read(uint8_t reg, int64_t t_ns) = 0;
  /// A read transaction begins at register `reg` (before its first byte).
  virtual void on_read_start(uint8_t /*reg*/, int64_t /*t_ns*/) {}
  /// A read transaction that began at `first` ended after `count` bytes.
  virtual void on_read_end(uint8_t /*first*/, int /*count*/, int64_t /*t_ns*/) {}
  [[nodiscard]] virtual uint8_t next_pointer(uint8_t reg) const { return static_cast<uint8_t>(reg + 1); }

 private:
  uint8_t pointer_ = 0;
  bool reading_ = false;
  bool pointer_written_ = false;
  uint8_t first_ = 0;
  int count_ = 0;
};

/// The bus: routes the master's conditions to the device at the addressed 7-bit address. A read
/// with nobody driving SDA returns 0xFF (the pull-ups).
class I2cBus {
 public:
  void attach(I2cDevice* device) { devices_.push_back(device); }
  bool start(uint8_t address_byte, int64_t t_ns);  ///< SLA+R/W; true: ACK
  bool write(uint8_t byte, int64_t t_ns);
  uint8_t read(int64_t t_ns);
  void stop(int64_t t_ns);
  [[nodiscard]] const std::vector<I2cDevice*>& devices() const { return devices_; }

 private:
  std::vector<I2cDevice*> devices_;
  I2cDevice* selected_ = nullptr;
};

}  // namespace poise::firmware_emu
