// Simulated I2C bus for the firmware test: register files per 7-bit address, auto-increment on
// reads, and a BMP180 model that latches UT/UP into 0xF6.. when a conversion is started.
#pragma once

#include <cstdint>
#include <vector>

struct MockWire {
  uint8_t regs[128][256] = {};
  bool present[128] = {};
  uint8_t ptr[128] = {};
  uint8_t addr = 0;
  bool first = true;
  std::vector<uint8_t> rx;
  std::size_t pos = 0;
  int32_t bmp_ut = 0;  // raw temperature the simulated BMP180 returns
  int32_t bmp_up = 0;  // raw pressure (before the >> (8 - oss) shift)

  void begin() {}
  void setClock(uint32_t) {}
  void beginTransmission(uint8_t a) {
    addr = a;
    first = true;
  }
  std::size_t write(uint8_t v) {
    if (first) {
      ptr[addr] = v;
      first = false;
      return 1;
    }
    const uint8_t r = ptr[addr]++;
    regs[addr][r] = v;
    if (addr == 0x77 && r == 0xF4) {
      if (v == 0x2E) {
        regs[addr][0xF6] = static_cast<uint8_t>(bmp_ut >> 8);
        regs[addr][0xF7] = static_cast<uint8_t>(bmp_ut & 0xFF);
      } else {
        const int oss = v >> 6;
        const int32_t up = bmp_up << (8 - oss);
        regs[addr][0xF6] = static_cast<uint8_t>(up >> 16);
        regs[addr][0xF7] = static_cast<uint8_t>(up >> 8);
        regs[addr][0xF8] = static_cast<uint8_t>(up & 0xFF);
      }
    }
    return 1;
  }
  uint8_t endTransmission(bool = true) { return present[addr] ? 0 : 2; }
  uint8_t requestFrom(uint8_t a, uint8_t n) {
    if (!present[a]) return 0;
    rx.clear();
    pos = 0;
    for (uint8_t i = 0; i < n; ++i) rx.push_back(regs[a][static_cast<uint8_t>(ptr[a] + i)]);
    ptr[a] = static_cast<uint8_t>(ptr[a] + n);
    return n;
  }
  int read() { return pos < rx.size() ? rx[pos++] : -1; }
};
extern MockWire Wire;
