// gy87_poise: GY-87 (MPU6050 + HMC5883L or QMC5883L + BMP180) -> poise serial IMU protocol.
// Reference firmware for `poise imu` (protocol: docs/SERIAL_PROTOCOL.md in the poise repository).
// Arduino core only (Wire, Serial); no external libraries. Tested layout: GY-87 on the I2C pins
// (Uno/Nano: A4 = SDA, A5 = SCL), VCC 5 V (the board has its own regulator), GND.
//
// One line per sample:
//   $IMU,<seq>,<t_us>,<ax>,<ay>,<az>,<gx>,<gy>,<gz>,<mx>,<my>,<mz>,<p_pa>,<temp_c>*<CS>\r\n
// or, with OUTPUT_RAW 1, the register counts:
//   $RAW,<seq>,<t_us>,<ax>,<ay>,<az>,<gx>,<gy>,<gz>,<mx>,<my>,<mz>,<p_pa>,<mpu_temp_counts>*<CS>\r\n
// and, at start and every INFO_EVERY samples, what the sensor is (its low-pass setting, from which
// the driver knows the delay of the samples: the MPU6050 register map's DLPF_CFG table):
//   $INF,1,MPU6050,<DLPF_CFG>,,*<CS>\r\n
// CS = XOR of every character between '$' and '*', two uppercase hex digits.
// Messages for humans start with '#' (the driver logs them and never counts them as errors).
// The three magnetometer fields are left empty when there is no magnetometer, it saturated or it
// stopped answering; the pressure field is empty while the BMP180 does not answer.
// Build and flash with Debian's arduino-mk: `make upload` here (Makefile; docs/FIRMWARE.md). The
// AVR binary is tested on simavr with models of the sensors (tests/firmware).

#include <Wire.h>

// ------------------------------------------------------------------ configuration
#ifndef BAUD
#define BAUD 115200UL            // must match `poise imu --baud` (9600 .. 1000000)
#endif
#ifndef SAMPLE_PERIOD_US
#define SAMPLE_PERIOD_US 10000UL // 100 Hz; ~95-byte lines need ~9.5 kB/s (115200 baud = 11.5 kB/s)
#endif
#ifndef OUTPUT_RAW
#define OUTPUT_RAW 0             // 1: $RAW register counts (shorter lines, convert on the host)
#endif

// Ranges (must match raw.* in the driver YAML when OUTPUT_RAW is 1).
#ifndef ACCEL_FS_SEL
#define ACCEL_FS_SEL 1           // 0: +-2 g, 1: +-4 g, 2: +-8 g, 3: +-16 g
#endif
#ifndef GYRO_FS_SEL
#define GYRO_FS_SEL 1            // 0: 250, 1: 500, 2: 1000, 3: 2000 deg/s
#endif
#ifndef DLPF_CFG
#define DLPF_CFG 3               // MPU6050 digital low-pass filter (CONFIG 0x1A), 0..6: 3 = accel
#endif                           // 44 Hz / 4.9 ms, gyro 42 Hz / 4.8 ms (the driver has the table)
#if DLPF_CFG < 0 || DLPF_CFG > 6
#error "DLPF_CFG must be 0..6 (7 is reserved)"
#endif
#ifndef INFO_EVERY
#define INFO_EVERY 100           // samples between $INF lines (a driver that attaches late learns
#endif                           // the delay within this many; 100 = 1 s at 100 Hz)
#ifndef BARO_OSS
#define BARO_OSS 1               // BMP180 oversampling 0..3
#endif

// ------------------------------------------------------------------ constants
static const uint8_t MPU_ADDR = 0x68;
static const uint8_t HMC_ADDR = 0x1E;
static const uint8_t QMC_ADDR = 0x0D;    // the QMC5883L of GY-87 clones
static const uint8_t BMP_ADDR = 0x77;
static const float G_MPS2 = 9.80665f;
static const float DEG2RAD = 0.017453292519943295f;
static const float ACCEL_LSB_PER_G = 16384.0f / (1 << ACCEL_FS_SEL);
static const float GYRO_LSB_PER_DPS = 131.0f / (1 << GYRO_FS_SEL);
static const float MAG_LSB_PER_GAUSS = 1090.0f;  // HMC5883L gain setting 1 (+-1.3 Ga)
static const float QMC_LSB_PER_GAUSS = 12000.0f; // QMC5883L range 2 G
// Time from waking the MPU6050 to the first sample: its gyro start-up time (30 ms, product
// specification 6.1) and the magnetometers' first measurement (HMC5883L 6 ms, QMC5883L 10 ms).
static const uint32_t STARTUP_WAIT_US = 35000UL;

// ------------------------------------------------------------------ I2C helpers
static bool writeReg(uint8_t addr, uint8_t reg, uint8_t value) {
  Wire.beginTransmission(addr);
  Wire.write(reg);
  Wire.write(value);
  return Wire.endTransmission() == 0;
}

static bool readRegs(uint8_t addr, uint8_t reg, uint8_t* buf, uint8_t n) {
  Wire.beginTransmission(addr);
  Wire.write(reg);
  if (Wire.endTransmission(false) != 0) return false;
  if (Wire.requestFrom(addr, n) != n) return false;
  for (uint8_t i = 0; i < n; ++i) buf[i] = Wire.read();
  return true;
}

static int16_t be16(const uint8_t* p) { return (int16_t)(((uint16_t)p[0] << 8) | p[1]); }
static int16_t le16(const uint8_t* p) { return (int16_t)(((uint16_t)p[1] << 8) | p[0]); }

// ------------------------------------------------------------------ line building
static char line[160];
static uint8_t len;

static void put(char c) {
  if (len < sizeof(line) - 6) line[len++] = c;
}
static void putStr(const char* s) {
  while (*s) put(*s++);
}
// Digits come from ultoa() (avr-libc converts with a fast divide-by-ten; also in the SAMD and
// ESP32 cores). A generic 32-bit division per digit cost about 7 ms per line on the 16 MHz AVR,
// which with the I2C reads and the serial buffer left less than the 10 ms sample period (the
// emulated board measured 97.6 Hz instead of 100; tests/firmware, docs/FIRMWARE.md).
static void putUnsigned(uint32_t v) {
  char tmp[11];
  putStr(ultoa(v, tmp, 10));
}
static void putSigned(int32_t v) {
  if (v < 0) {
    put('-');
    putUnsigned((uint32_t)(-(v + 1)) + 1);
  } else {
    putUnsigned((uint32_t)v);
  }
}
// Fixed-point decimal without printf/dtostrf (portable across AVR, SAMD, ESP32).
static void putFloat(float v, uint8_t decimals) {
  if (!(v == v)) {  // NaN: send it, the driver rejects and counts it
    putStr("nan");
    return;
  }
  uint32_t scale = 1;
  for (uint8_t i = 0; i < decimals; ++i) scale *= 10;
  if (v < 0) {
    put('-');
    v = -v;
  }
  if (v > 2.0e9f / scale) v = 2.0e9f / scale;  // keep within uint32 (out-of-range for the driver)
  char digits[11];
  ultoa((uint32_t)(v * scale + 0.5f), digits, 10);
  const uint8_t n = (uint8_t)strlen(digits);
  if (n <= decimals) {  // below 1: "0." and the leading zeros of the fraction
    put('0');
    put('.');
    for (uint8_t i = n; i < decimals; ++i) put('0');
    putStr(digits);
    return;
  }
  for (uint8_t i = 0; i < n - decimals; ++i) put(digits[i]);
  if (decimals > 0) {
    put('.');
    putStr(digits + n - decimals);
  }
}
static void finishAndSend() {
  uint8_t cs = 0;
  for (uint8_t i = 1; i < len; ++i) cs ^= (uint8_t)line[i];  // between '$' and '*'
  static const char hex[] = "0123456789ABCDEF";
  line[len++] = '*';
  line[len++] = hex[cs >> 4];
  line[len++] = hex[cs & 0x0F];
  line[len++] = '\r';
  line[len++] = '\n';
  Serial.write((const uint8_t*)line, len);
}

// The sensor info line (docs/SERIAL_PROTOCOL.md "Sensor info"): version 1, chip, setting; the
// delay fields stay empty (the driver's datasheet table is the one copy of the figures).
static void sendInfo() {
  len = 0;
  putStr("$INF,1,MPU6050,");
  putUnsigned(DLPF_CFG);
  putStr(",,");
  finishAndSend();
}

// ------------------------------------------------------------------ BMP180
struct Bmp180Cal {
  int16_t ac1, ac2, ac3;
  uint16_t ac4, ac5, ac6;
  int16_t b1, b2, mb, mc, md;
};
static Bmp180Cal bmp;
static bool haveBmp = false;
static int32_t pressurePa = 0;
static bool havePressure = false;
static float bmpTempC = 0;
// Non-blocking conversion: 0 idle -> 1 temperature running -> 2 pressure running.
static uint8_t bmpState = 0;
static uint32_t bmpReadyAtUs = 0;
static int32_t bmpUT = 0;

static bool bmpInit() {
  uint8_t id = 0;
  if (!readRegs(BMP_ADDR, 0xD0, &id, 1) || id != 0x55) return false;
  uint8_t c[22];
  if (!readRegs(BMP_ADDR, 0xAA, c, 22)) return false;
  bmp.ac1 = be16(c + 0);
  bmp.ac2 = be16(c + 2);
  bmp.ac3 = be16(c + 4);
  bmp.ac4 = (uint16_t)be16(c + 6);
  bmp.ac5 = (uint16_t)be16(c + 8);
  bmp.ac6 = (uint16_t)be16(c + 10);
  bmp.b1 = be16(c + 12);
  bmp.b2 = be16(c + 14);
  bmp.mb = be16(c + 16);
  bmp.mc = be16(c + 18);
  bmp.md = be16(c + 20);
  return true;
}

// Datasheet compensation (integer arithmetic as specified by Bosch).
static void bmpCompute(int32_t ut, int32_t up) {
  int32_t x1 = ((ut - (int32_t)bmp.ac6) * (int32_t)bmp.ac5) >> 15;
  int32_t x2 = ((int32_t)bmp.mc << 11) / (x1 + bmp.md);
  int32_t b5 = x1 + x2;
  bmpTempC = ((b5 + 8) >> 4) / 10.0f;
  int32_t b6 = b5 - 4000;
  x1 = ((int32_t)bmp.b2 * ((b6 * b6) >> 12)) >> 11;
  x2 = ((int32_t)bmp.ac2 * b6) >> 11;
  int32_t x3 = x1 + x2;
  int32_t b3 = ((((int32_t)bmp.ac1 * 4 + x3) << BARO_OSS) + 2) / 4;
  x1 = ((int32_t)bmp.ac3 * b6) >> 13;
  x2 = ((int32_t)bmp.b1 * ((b6 * b6) >> 12)) >> 16;
  x3 = ((x1 + x2) + 2) >> 2;
  uint32_t b4 = ((uint32_t)bmp.ac4 * (uint32_t)(x3 + 32768)) >> 15;
  uint32_t b7 = ((uint32_t)up - (uint32_t)b3) * (uint32_t)(50000UL >> BARO_OSS);
  int32_t p = (b7 < 0x80000000UL) ? (int32_t)((b7 * 2) / b4) : (int32_t)((b7 / b4) * 2);
  x1 = (p >> 8) * (p >> 8);
  x1 = (x1 * 3038) >> 16;
  x2 = (-7357 * p) >> 16;
  pressurePa = p + ((x1 + x2 + 3791) >> 4);
  havePressure = true;
}

// A failed transfer empties the pressure field until a whole new cycle succeeds (a stale
// pressure must not look fresh) and says so once.
static bool bmpFailed(bool ok) {
  if (ok) return false;
  if (havePressure) Serial.print(F("# error: BMP180 not answering: pressure empty until it does\r\n"));
  havePressure = false;
  bmpState = 0;
  return true;
}

static void bmpStep(uint32_t nowUs) {
  if (!haveBmp) return;
  if (bmpState != 0 && (int32_t)(nowUs - bmpReadyAtUs) < 0) return;
  uint8_t b[3];
  switch (bmpState) {
    case 0:
      if (bmpFailed(writeReg(BMP_ADDR, 0xF4, 0x2E))) return;  // temperature
      bmpReadyAtUs = nowUs + 5000;
      bmpState = 1;
      break;
    case 1:
      if (bmpFailed(readRegs(BMP_ADDR, 0xF6, b, 2))) return;
      bmpUT = ((int32_t)b[0] << 8) | b[1];
      if (bmpFailed(writeReg(BMP_ADDR, 0xF4, (uint8_t)(0x34 + (BARO_OSS << 6))))) return;  // pressure
      bmpReadyAtUs = nowUs + 2000UL + 3000UL * (1UL << BARO_OSS) + 500UL;
      bmpState = 2;
      break;
    default:
      if (bmpFailed(readRegs(BMP_ADDR, 0xF6, b, 3))) return;
      bmpCompute(bmpUT, (((int32_t)b[0] << 16) | ((int32_t)b[1] << 8) | b[2]) >> (8 - BARO_OSS));
      bmpState = 0;
      break;
  }
}

// ------------------------------------------------------------------ magnetometer
enum MagChip : uint8_t { MAG_NONE, MAG_HMC, MAG_QMC };
static MagChip mag = MAG_NONE;
static int16_t lastMag[3] = {0, 0, 0};  // X, Y, Z counts of the last measurement read
static bool magValid = false;           // lastMag holds a measurement read since the last failure
static bool magOverflow = false;        // the chip flagged that measurement as out of range

static void magInit() {
  uint8_t id[3];
  if (readRegs(HMC_ADDR, 0x0A, id, 3) && id[0] == 'H' && id[1] == '4' && id[2] == '3') {
    mag = MAG_HMC;
    writeReg(HMC_ADDR, 0x00, 0x18);  // 1 average, 75 Hz, normal measurement
    writeReg(HMC_ADDR, 0x01, 0x20);  // gain 1090 LSB/Ga (+-1.3 Ga)
    writeReg(HMC_ADDR, 0x02, 0x00);  // continuous mode
  } else if (readRegs(QMC_ADDR, 0x0D, id, 1) && id[0] == 0xFF) {
    mag = MAG_QMC;
    writeReg(QMC_ADDR, 0x0A, 0x80);  // soft reset
    writeReg(QMC_ADDR, 0x0B, 0x01);  // SET/RESET period (datasheet: 0x01)
    writeReg(QMC_ADDR, 0x09, 0x09);  // OSR 512, 2 G, 100 Hz, continuous
    Serial.print(F("# QMC5883L magnetometer at 0x0D\r\n"));
  } else {
    Serial.print(F("# warning: no magnetometer (HMC5883L at 0x1E, QMC5883L at 0x0D): mag fields stay empty\r\n"));
  }
}

// Reads the magnetometer once per sample; lastMag keeps the latest measurement (the HMC5883L
// measures at 75 Hz, the QMC5883L at 100 Hz). A failed transfer empties the fields until a new
// measurement is read, and says so once.
static void magStep() {
  uint8_t m[6];
  bool ok;
  if (mag == MAG_HMC) {
    ok = readRegs(HMC_ADDR, 0x03, m, 6);  // all six: a partial read locks the data registers
    if (ok) {
      lastMag[0] = be16(m + 0);  // register order X, Z, Y
      lastMag[2] = be16(m + 2);
      lastMag[1] = be16(m + 4);
      magOverflow = lastMag[0] == -4096 || lastMag[1] == -4096 || lastMag[2] == -4096;  // its marker
    }
  } else {
    uint8_t status = 0;
    ok = readRegs(QMC_ADDR, 0x06, &status, 1);
    if (ok && (status & 0x01)) {  // DRDY: a new measurement (reading the data clears it)
      ok = readRegs(QMC_ADDR, 0x00, m, 6);
      if (ok) {
        lastMag[0] = le16(m + 0);
        lastMag[1] = le16(m + 2);
        lastMag[2] = le16(m + 4);
        // OVL. Not the HMC5883L's -4096 marker: at 12000 LSB/G -4096 is a valid reading
        // (-34.13 uT; the emulated board crossed it and the sample lost its magnetometer).
        magOverflow = (status & 0x02) != 0;
      }
    } else if (ok && !magValid) {
      return;  // answering again, but no new measurement yet
    }
  }
  if (!ok && magValid) Serial.print(F("# error: magnetometer not answering: mag empty until it does\r\n"));
  magValid = ok;
}

// ------------------------------------------------------------------ setup / loop
static uint32_t seq = 0;
static uint32_t nextUs = 0;

void setup() {
  Serial.begin(BAUD);
  Wire.begin();
  Wire.setClock(400000);
  delay(100);
  Serial.print(F("# gy87_poise v1 starting\r\n"));
  uint8_t who = 0;
  if (!readRegs(MPU_ADDR, 0x75, &who, 1) || (who != 0x68 && who != 0x72)) {
    Serial.print(F("# error: MPU6050 not found at 0x68 (check wiring: SDA, SCL, VCC, GND)\r\n"));
  }
  writeReg(MPU_ADDR, 0x6B, 0x01);                       // wake up, clock = PLL with X gyro
  const uint32_t wokeUs = micros();
  writeReg(MPU_ADDR, 0x19, 0x00);                       // sample rate divider: 1 kHz
  writeReg(MPU_ADDR, 0x1A, DLPF_CFG);                   // DLPF (3: 44 Hz, 4.9 ms)
  writeReg(MPU_ADDR, 0x1B, (uint8_t)(GYRO_FS_SEL << 3));
  writeReg(MPU_ADDR, 0x1C, (uint8_t)(ACCEL_FS_SEL << 3));
  writeReg(MPU_ADDR, 0x6A, 0x00);                       // I2C master off
  writeReg(MPU_ADDR, 0x37, 0x02);                       // bypass: HMC5883L on the main bus
  magInit();
  haveBmp = bmpInit();
  if (!haveBmp) Serial.print(F("# warning: BMP180 not found: pressure fields stay empty\r\n"));
  while ((uint32_t)(micros() - wokeUs) < STARTUP_WAIT_US) {
  }
  Serial.print(F("# gy87_poise v1 ready\r\n"));
  sendInfo();
  nextUs = micros();
}

void loop() {
  const uint32_t now = micros();
  bmpStep(now);
  if ((int32_t)(now - nextUs) < 0) return;
  nextUs += SAMPLE_PERIOD_US;
  if ((int32_t)(now - nextUs) > (int32_t)(10 * SAMPLE_PERIOD_US)) nextUs = now;  // fell behind

  const uint32_t tUs = micros();  // sampling instant (start of the register read)
  uint8_t b[14];
  if (!readRegs(MPU_ADDR, 0x3B, b, 14)) {
    Serial.print(F("# error: MPU6050 read failed\r\n"));
    ++seq;  // the host sees the gap
    return;
  }
  int16_t ax = be16(b + 0), ay = be16(b + 2), az = be16(b + 4);
  int16_t tc = be16(b + 6);
  int16_t gx = be16(b + 8), gy = be16(b + 10), gz = be16(b + 12);
  if (mag != MAG_NONE) magStep();

  len = 0;
#if OUTPUT_RAW
  putStr("$RAW,");
  putUnsigned(seq++); put(',');
  putUnsigned(tUs); put(',');
  putSigned(ax); put(','); putSigned(ay); put(','); putSigned(az); put(',');
  putSigned(gx); put(','); putSigned(gy); put(','); putSigned(gz); put(',');
  if (magValid && magOverflow) {
    putStr("-4096,-4096,-4096,");  // the overflow marker: the driver flags the sample's mag invalid
  } else if (magValid) {  // a QMC5883L reading of -4096 would read as the marker: sent as -4095
    for (uint8_t i = 0; i < 3; ++i) {
      putSigned(lastMag[i] == -4096 ? -4095 : lastMag[i]);
      put(',');
    }
  } else {
    putStr(",,,");
  }
  if (havePressure) putSigned(pressurePa);
  put(',');
  putSigned(tc);
#else
  const float ka = G_MPS2 / ACCEL_LSB_PER_G;
  const float kg = DEG2RAD / GYRO_LSB_PER_DPS;
  const float km = 100.0f / (mag == MAG_QMC ? QMC_LSB_PER_GAUSS : MAG_LSB_PER_GAUSS);  // uT/count
  putStr("$IMU,");
  putUnsigned(seq++); put(',');
  putUnsigned(tUs); put(',');
  putFloat(ax * ka, 3); put(','); putFloat(ay * ka, 3); put(','); putFloat(az * ka, 3); put(',');
  putFloat(gx * kg, 4); put(','); putFloat(gy * kg, 4); put(','); putFloat(gz * kg, 4); put(',');
  if (magValid && !magOverflow) {
    putFloat(lastMag[0] * km, 2); put(','); putFloat(lastMag[1] * km, 2); put(',');
    putFloat(lastMag[2] * km, 2); put(',');
  } else {
    putStr(",,,");  // no magnetometer / overflow / not answering: the driver flags has_mag = false
  }
  if (havePressure) putSigned(pressurePa);
  put(',');
  putFloat(tc / 340.0f + 36.53f, 2);
#endif
  finishAndSend();
  if (seq % INFO_EVERY == 0) sendInfo();  // after the sample: its timing is untouched
}
