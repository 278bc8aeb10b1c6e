#include "poise/imu/protocol.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>

namespace poise::imu {
namespace {

constexpr std::size_t kValueFields = 13;  // seq, t_us, 9 vector components, pressure, temperature
constexpr double kPi = 3.14159265358979323846;
constexpr double kUtPerGauss = 100.0;
constexpr int32_t kHmcOverflow = -4096;  // HMC5883L data register value on ADC overflow

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

enum class FieldStatus { kOk, kEmpty, kNonNumeric, kNotFinite, kOutOfRange };

FieldStatus parse_u32(std::string_view f, uint32_t* out) {
  if (f.empty()) return FieldStatus::kEmpty;
  uint64_t v = 0;
  const auto r = std::from_chars(f.data(), f.data() + f.size(), v);
  if (r.ec == std::errc::result_out_of_range) return FieldStatus::kOutOfRange;
  if (r.ec != std::errc() || r.ptr != f.data() + f.size()) return FieldStatus::kNonNumeric;
  if (v > std::numeric_limits<uint32_t>::max()) return FieldStatus::kOutOfRange;
  *out = static_cast<uint32_t>(v);
  return FieldStatus::kOk;
}

FieldStatus parse_double(std::string_view f, double* out) {
  if (f.empty()) return FieldStatus::kEmpty;
  if (f.front() == '+') f.remove_prefix(1);
  if (f.empty() || f.front() == '+' || f.front() == ' ') return FieldStatus::kNonNumeric;
  double v = 0.0;
  const auto r = std::from_chars(f.data(), f.data() + f.size(), v, std::chars_format::general);
  if (r.ec == std::errc::result_out_of_range) return FieldStatus::kOutOfRange;
  if (r.ec != std::errc() || r.ptr != f.data() + f.size()) return FieldStatus::kNonNumeric;
  if (!std::isfinite(v)) return FieldStatus::kNotFinite;
  *out = v;
  return FieldStatus::kOk;
}

FieldStatus parse_i32(std::string_view f, int32_t* out) {
  if (f.empty()) return FieldStatus::kEmpty;
  if (f.front() == '+') f.remove_prefix(1);
  if (f.empty() || f.front() == '+') return FieldStatus::kNonNumeric;
  int64_t v = 0;
  const auto r = std::from_chars(f.data(), f.data() + f.size(), v);
  if (r.ec == std::errc::result_out_of_range) return FieldStatus::kOutOfRange;
  if (r.ec != std::errc() || r.ptr != f.data() + f.size()) {
    // A float where an integer is expected, or anything else that is not an integer.
    return FieldStatus::kNonNumeric;
  }
  if (v < std::numeric_limits<int32_t>::min() || v > std::numeric_limits<int32_t>::max()) {
    return FieldStatus::kOutOfRange;
  }
  *out = static_cast<int32_t>(v);
  return FieldStatus::kOk;
}

RejectReason reason_of(FieldStatus s) {
  switch (s) {
    case FieldStatus::kEmpty: return RejectReason::kMissingField;
    case FieldStatus::kNonNumeric: return RejectReason::kNonNumeric;
    case FieldStatus::kNotFinite: return RejectReason::kNotFinite;
    case FieldStatus::kOutOfRange: return RejectReason::kOutOfRange;
    case FieldStatus::kOk: break;
  }
  return RejectReason::kGarbage;  // unreachable for kOk; callers only map failures
}

ParseResult reject(RejectReason r) {
  ParseResult out;
  out.ok = false;
  out.reason = r;
  return out;
}

bool within(const Eigen::Vector3d& v, double max_abs) { return v.cwiseAbs().maxCoeff() <= max_abs; }

bool chip_name_ok(std::string_view chip) {
  if (chip.empty() || chip.size() > 16) return false;
  for (const char c : chip) {
    const bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '-';
    if (!ok) return false;
  }
  return true;
}

// "$INF,<version>,<chip>,<setting>,<accel_delay_us>,<gyro_delay_us>": `rest` is the text after
// "INF,". The version comes first so that a later version (other fields) is counted, not misread.
ParseResult parse_info(std::string_view rest) {
  constexpr std::size_t kInfoFields = 5;
  std::array<std::string_view, kInfoFields> f{};
  std::size_t n = 0;
  std::size_t start = 0;
  while (true) {
    const std::size_t next = rest.find(',', start);
    if (n == kInfoFields) {
      n = kInfoFields + 1;
      break;
    }
    f[n++] = rest.substr(start, next == std::string_view::npos ? next : next - start);
    if (next == std::string_view::npos) break;
    start = next + 1;
  }
  ParseResult out;
  SensorInfoLine& info = out.info;
  FieldStatus st = parse_u32(f[0], &info.version);
  if (st != FieldStatus::kOk) return reject(reason_of(st));
  if (info.version != 1) return reject(RejectReason::kInfoUnsupported);
  if (n != kInfoFields) return reject(RejectReason::kFieldCount);
  if (!chip_name_ok(f[1])) return reject(f[1].empty() ? RejectReason::kMissingField : RejectReason::kInfoUnsupported);
  info.chip.assign(f[1].data(), f[1].size());
  if (!f[2].empty()) {
    st = parse_i32(f[2], &info.setting);
    if (st != FieldStatus::kOk) return reject(reason_of(st));
    if (info.setting < 0 || info.setting > 255) return reject(RejectReason::kOutOfRange);
  }
  if (f[3].empty() != f[4].empty()) return reject(RejectReason::kMissingField);
  info.has_delays = !f[3].empty();
  if (info.has_delays) {
    for (int i = 0; i < 2; ++i) {
      uint32_t& d = i == 0 ? info.accel_delay_us : info.gyro_delay_us;
      st = parse_u32(f[3 + i], &d);
      if (st != FieldStatus::kOk) return reject(reason_of(st));
      if (d > kMaxInfoDelayUs) return reject(RejectReason::kOutOfRange);
    }
  }
  if (info.setting < 0 && !info.has_delays) return reject(RejectReason::kMissingField);
  out.ok = true;
  out.is_info = true;
  return out;
}

}  // namespace

const char* to_string(RejectReason reason) {
  switch (reason) {
    case RejectReason::kGarbage: return "garbage";
    case RejectReason::kOverlong: return "overlong";
    case RejectReason::kTruncated: return "truncated";
    case RejectReason::kBadChecksumField: return "bad_checksum_field";
    case RejectReason::kChecksumMismatch: return "checksum_mismatch";
    case RejectReason::kUnknownSentence: return "unknown_sentence";
    case RejectReason::kFieldCount: return "field_count";
    case RejectReason::kMissingField: return "missing_field";
    case RejectReason::kNonNumeric: return "non_numeric";
    case RejectReason::kNotFinite: return "not_finite";
    case RejectReason::kOutOfRange: return "out_of_range";
    case RejectReason::kDuplicateSeq: return "duplicate_seq";
    case RejectReason::kOutOfOrderSeq: return "out_of_order_seq";
    case RejectReason::kTimeNotMonotonic: return "time_not_monotonic";
    case RejectReason::kInfoUnsupported: return "info_unsupported";
    case RejectReason::kInfoUnknownSetting: return "info_unknown_setting";
    case RejectReason::kInfoConflict: return "info_conflict";
    case RejectReason::kCount: break;
  }
  return "unknown";
}

uint8_t nmea_checksum(std::string_view payload) {
  uint8_t cs = 0;
  for (const char c : payload) cs = static_cast<uint8_t>(cs ^ static_cast<uint8_t>(c));
  return cs;
}

// not split: the line grammar of docs/SERIAL_PROTOCOL.md field by field, each rejection named where
// its field is read.
ParseResult LineParser::parse(std::string_view line) const {
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  if (line.size() > kMaxLineBytes) return reject(RejectReason::kOverlong);
  if (line.empty() || line.front() != '$') return reject(RejectReason::kGarbage);

  const std::size_t star = line.find('*');
  if (star == std::string_view::npos) return reject(RejectReason::kTruncated);
  const std::string_view cs_text = line.substr(star + 1);
  if (cs_text.size() < 2) return reject(RejectReason::kTruncated);
  if (cs_text.size() > 2) return reject(RejectReason::kBadChecksumField);
  const int hi = hex_value(cs_text[0]);
  const int lo = hex_value(cs_text[1]);
  if (hi < 0 || lo < 0) return reject(RejectReason::kBadChecksumField);
  const std::string_view payload = line.substr(1, star - 1);
  if (nmea_checksum(payload) != static_cast<uint8_t>(hi * 16 + lo)) {
    return reject(RejectReason::kChecksumMismatch);
  }

  // Split "TALKER,f0,...,f13" without allocating.
  std::array<std::string_view, kValueFields> fields{};
  std::size_t comma = payload.find(',');
  const std::string_view talker = payload.substr(0, comma);
  bool raw = false;
  if (talker == "INF") {
    if (comma == std::string_view::npos) return reject(RejectReason::kFieldCount);
    return parse_info(payload.substr(comma + 1));
  }
  if (talker == "IMU") {
    raw = false;
  } else if (talker == "RAW") {
    raw = true;
  } else {
    return reject(RejectReason::kUnknownSentence);
  }
  if (comma == std::string_view::npos) return reject(RejectReason::kFieldCount);
  std::size_t n = 0;
  std::size_t start = comma + 1;
  while (true) {
    const std::size_t next = payload.find(',', start);
    if (n == kValueFields) return reject(RejectReason::kFieldCount);
    fields[n++] = payload.substr(start, next == std::string_view::npos ? next : next - start);
    if (next == std::string_view::npos) break;
    start = next + 1;
  }
  if (n != kValueFields) return reject(RejectReason::kFieldCount);

  ParseResult out;
  RawSample& s = out.sample;
  s.from_raw_counts = raw;
  FieldStatus st = parse_u32(fields[0], &s.seq);
  if (st != FieldStatus::kOk) return reject(reason_of(st));
  st = parse_u32(fields[1], &s.t_us);
  if (st != FieldStatus::kOk) return reject(reason_of(st));

  if (!raw) {
    std::array<double, 9> v{};
    s.has_mag = !(fields[8].empty() && fields[9].empty() && fields[10].empty());
    for (std::size_t i = 0; i < 9; ++i) {
      if (i >= 6 && !s.has_mag) break;
      st = parse_double(fields[2 + i], &v[i]);
      if (st != FieldStatus::kOk) return reject(reason_of(st));
    }
    s.accel_mps2 = Eigen::Vector3d(v[0], v[1], v[2]);
    s.gyro_rps = Eigen::Vector3d(v[3], v[4], v[5]);
    s.mag_ut = Eigen::Vector3d(v[6], v[7], v[8]);
    st = parse_double(fields[11], &s.pressure_pa);
    if (st != FieldStatus::kOk && st != FieldStatus::kEmpty) return reject(reason_of(st));
    s.has_pressure = st == FieldStatus::kOk;
    st = parse_double(fields[12], &s.temperature_c);
    if (st != FieldStatus::kOk && st != FieldStatus::kEmpty) return reject(reason_of(st));
    s.has_temperature = st == FieldStatus::kOk;
  } else {
    std::array<int32_t, 9> c{};
    s.has_mag = !(fields[8].empty() && fields[9].empty() && fields[10].empty());
    for (std::size_t i = 0; i < 9; ++i) {
      if (i >= 6 && !s.has_mag) break;
      st = parse_i32(fields[2 + i], &c[i]);
      if (st != FieldStatus::kOk) return reject(reason_of(st));
      if (c[i] < std::numeric_limits<int16_t>::min() || c[i] > std::numeric_limits<int16_t>::max()) {
        return reject(RejectReason::kOutOfRange);
      }
    }
    if (s.has_mag && (c[6] == kHmcOverflow || c[7] == kHmcOverflow || c[8] == kHmcOverflow)) {
      s.has_mag = false;  // saturated: the sample stays, its magnetometer is flagged invalid
      c[6] = c[7] = c[8] = 0;
    }
    const double accel_k = raw_.g_mps2 / raw_.accel_lsb_per_g;
    const double gyro_k = kPi / 180.0 / raw_.gyro_lsb_per_dps;
    const double mag_k = kUtPerGauss / raw_.mag_lsb_per_gauss;
    s.accel_mps2 = accel_k * Eigen::Vector3d(c[0], c[1], c[2]);
    s.gyro_rps = gyro_k * Eigen::Vector3d(c[3], c[4], c[5]);
    s.mag_ut = mag_k * Eigen::Vector3d(c[6], c[7], c[8]);
    int32_t p = 0;
    st = parse_i32(fields[11], &p);
    if (st != FieldStatus::kOk && st != FieldStatus::kEmpty) return reject(reason_of(st));
    s.has_pressure = st == FieldStatus::kOk;
    s.pressure_pa = static_cast<double>(p);
    int32_t t = 0;
    st = parse_i32(fields[12], &t);
    if (st != FieldStatus::kOk && st != FieldStatus::kEmpty) return reject(reason_of(st));
    if (st == FieldStatus::kOk && (t < std::numeric_limits<int16_t>::min() ||
                                   t > std::numeric_limits<int16_t>::max())) {
      return reject(RejectReason::kOutOfRange);
    }
    s.has_temperature = st == FieldStatus::kOk;
    s.temperature_c = static_cast<double>(t) / raw_.temp_lsb_per_c + raw_.temp_offset_c;
  }
  if (!within(s.accel_mps2, limits_.accel_max_mps2) || !within(s.gyro_rps, limits_.gyro_max_rps) ||
      !within(s.mag_ut, limits_.mag_max_ut)) {
    return reject(RejectReason::kOutOfRange);
  }
  if (s.has_pressure &&
      (s.pressure_pa < limits_.pressure_min_pa || s.pressure_pa > limits_.pressure_max_pa)) {
    return reject(RejectReason::kOutOfRange);
  }
  if (s.has_temperature && (s.temperature_c < limits_.temperature_min_c ||
                            s.temperature_c > limits_.temperature_max_c)) {
    return reject(RejectReason::kOutOfRange);
  }
  out.ok = true;
  return out;
}

std::string format_info_line(const SensorInfoLine& info) {
  std::string p = "INF," + std::to_string(info.version) + "," + info.chip + ",";
  if (info.setting >= 0) p += std::to_string(info.setting);
  p += ",";
  if (info.has_delays) p += std::to_string(info.accel_delay_us) + "," + std::to_string(info.gyro_delay_us);
  else p += ",";
  return wrap_payload(p);
}

std::string wrap_payload(std::string_view payload) {
  char tail[8];
  std::snprintf(tail, sizeof tail, "*%02X\r\n", static_cast<unsigned>(nmea_checksum(payload)));
  std::string line;
  line.reserve(payload.size() + 7);
  line += '$';
  line += payload;
  line += tail;
  return line;
}

std::string format_imu_line(const RawSample& s, int decimals) {
  char buf[512];
  int n = std::snprintf(buf, sizeof buf, "IMU,%u,%u,%.*f,%.*f,%.*f,%.*f,%.*f,%.*f,",
                        static_cast<unsigned>(s.seq), static_cast<unsigned>(s.t_us), decimals,
                        s.accel_mps2.x(), decimals, s.accel_mps2.y(), decimals, s.accel_mps2.z(),
                        decimals, s.gyro_rps.x(), decimals, s.gyro_rps.y(), decimals,
                        s.gyro_rps.z());
  std::string payload(buf, static_cast<std::size_t>(n));
  if (s.has_mag) {
    n = std::snprintf(buf, sizeof buf, "%.*f,%.*f,%.*f,", decimals, s.mag_ut.x(), decimals,
                      s.mag_ut.y(), decimals, s.mag_ut.z());
    payload.append(buf, static_cast<std::size_t>(n));
  } else {
    payload += ",,,";
  }
  if (s.has_pressure) {
    n = std::snprintf(buf, sizeof buf, "%.1f", s.pressure_pa);
    payload.append(buf, static_cast<std::size_t>(n));
  }
  payload += ',';
  if (s.has_temperature) {
    n = std::snprintf(buf, sizeof buf, "%.2f", s.temperature_c);
    payload.append(buf, static_cast<std::size_t>(n));
  }
  return wrap_payload(payload);
}

std::string format_raw_line(const RawCounts& c) {
  char buf[256];
  int n = std::snprintf(buf, sizeof buf, "RAW,%u,%u,%d,%d,%d,%d,%d,%d,",
                        static_cast<unsigned>(c.seq), static_cast<unsigned>(c.t_us), c.accel[0],
                        c.accel[1], c.accel[2], c.gyro[0], c.gyro[1], c.gyro[2]);
  std::string payload(buf, static_cast<std::size_t>(n));
  if (c.has_mag) {
    n = std::snprintf(buf, sizeof buf, "%d,%d,%d,", c.mag[0], c.mag[1], c.mag[2]);
    payload.append(buf, static_cast<std::size_t>(n));
  } else {
    payload += ",,,";
  }
  if (c.has_pressure) payload += std::to_string(c.pressure_pa);
  payload += ',';
  if (c.has_temperature) payload += std::to_string(c.temperature);
  return wrap_payload(payload);
}

}  // namespace poise::imu
