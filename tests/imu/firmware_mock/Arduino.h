// Minimal host-side stand-in for the Arduino core, enough to run tools/firmware/gy87_poise on a
// PC against a simulated I2C bus (see Wire.h) in tests. Not a general Arduino emulator.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

#define F(x) (x)

extern uint32_t mock_micros_now;
// avr-libc's ultoa (the AVR, SAMD and ESP32 cores have it; glibc does not).
inline char* ultoa(unsigned long v, char* buf, int radix) {
  char tmp[33];
  int n = 0;
  do {
    tmp[n++] = "0123456789abcdefghijklmnopqrstuvwxyz"[v % static_cast<unsigned long>(radix)];
    v /= static_cast<unsigned long>(radix);
  } while (v != 0);
  for (int i = 0; i < n; ++i) buf[i] = tmp[n - 1 - i];
  buf[n] = '\0';
  return buf;
}
// Each call advances the clock by 4 us (the AVR micros() resolution), so busy-waits end.
inline uint32_t micros() { return mock_micros_now += 4; }
inline void delay(unsigned long ms) { mock_micros_now += static_cast<uint32_t>(ms * 1000UL); }

struct MockSerial {
  std::string out;
  void begin(unsigned long) {}
  size_t print(const char* s) {
    out += s;
    return std::strlen(s);
  }
  size_t write(const uint8_t* b, size_t n) {
    out.append(reinterpret_cast<const char*>(b), n);
    return n;
  }
};
extern MockSerial Serial;
