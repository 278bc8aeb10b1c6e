#include "poise/firmware_emu/i2c.h"

namespace poise::firmware_emu {

bool I2cDevice::acknowledge(int64_t t_ns) {
  bool ack = reachable();
  for (const auto& [from, to] : nack_windows_) {
    if (t_ns >= from && t_ns < to) ack = false;
  }
  if (!ack) {
    ++nacks_;
    last_nack_ns_ = t_ns;
  }
  return ack;
}

void I2cDevice::violate(int64_t t_ns, std::string rule) {
  violations_.push_back({t_ns, name_, std::move(rule)});
}

void RegisterDevice::start(bool read, int64_t t_ns) {
  reading_ = read;
  pointer_written_ = false;
  first_ = pointer_;
  count_ = 0;
  if (read) on_read_start(pointer_, t_ns);
}

bool RegisterDevice::write(uint8_t byte, int64_t t_ns) {
  if (reading_) return false;
  if (!pointer_written_) {
    pointer_ = byte;
    pointer_written_ = true;
    return true;
  }
  on_write(pointer_, byte, t_ns);
  pointer_ = next_pointer(pointer_);
  return true;
}

uint8_t RegisterDevice::read(int64_t t_ns) {
  const uint8_t v = on_read(pointer_, t_ns);
  pointer_ = next_pointer(pointer_);
  ++count_;
  return v;
}

void RegisterDevice::stop(int64_t t_ns) {
  if (reading_) on_read_end(first_, count_, t_ns);
  reading_ = false;
  count_ = 0;
}

bool I2cBus::start(uint8_t address_byte, int64_t t_ns) {
  if (selected_ != nullptr) selected_->stop(t_ns);  // repeated start ends the transaction
  selected_ = nullptr;
  const uint8_t address = static_cast<uint8_t>(address_byte >> 1);
  for (I2cDevice* d : devices_) {
    if (d->address() == address && d->acknowledge(t_ns)) {
      selected_ = d;
      d->start((address_byte & 1) != 0, t_ns);
      return true;
    }
  }
  return false;
}

bool I2cBus::write(uint8_t byte, int64_t t_ns) {
  return selected_ != nullptr && selected_->write(byte, t_ns);
}

uint8_t I2cBus::read(int64_t t_ns) { return selected_ != nullptr ? selected_->read(t_ns) : 0xFF; }

void I2cBus::stop(int64_t t_ns) {
  if (selected_ != nullptr) selected_->stop(t_ns);
  selected_ = nullptr;
}

}  // namespace poise::firmware_emu
