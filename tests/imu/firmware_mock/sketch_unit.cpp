// Compiles the reference sketch for the host (with the mocks in this directory).
#include "Arduino.h"

uint32_t mock_micros_now = 0;
MockSerial Serial;
#include "Wire.h"
MockWire Wire;

#include "gy87_poise.ino"
