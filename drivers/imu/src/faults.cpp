#include "poise/imu/faults.h"

#include "poise/core/yaml_params.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "poise/imu/protocol.h"

namespace poise::imu {

const char* to_string(Fault f) {
  switch (f) {
    case Fault::kGarbage: return "garbage";
    case Fault::kDrop: return "drop";
    case Fault::kFlip: return "flip";
    case Fault::kTruncate: return "truncate";
    case Fault::kDup: return "dup";
    case Fault::kSwap: return "swap";
    case Fault::kNan: return "nan";
    case Fault::kCount: break;
  }
  return "unknown";
}

namespace {
/// A finite number (nan, inf and out-of-range values refused, naming the key: a NaN probability
/// would pass every range comparison).
double parse_number(const std::string& item, const std::string& text) {
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || text.empty()) {
    throw std::invalid_argument("fault spec item '" + item + "': '" + text + "' is not a number");
  }
  if (!std::isfinite(v)) {
    const std::string key = item.substr(0, item.find('='));
    throw std::invalid_argument("fault spec item '" + item + "': " + key + " must be a finite number, not '" +
                                text + "'");
  }
  return v;
}
}  // namespace

FaultSpec FaultSpec::parse(const std::string& spec) {
  FaultSpec out;
  if (spec.empty() || spec == "none") return out;
  std::stringstream ss(spec);
  std::string item;
  double total = 0;
  while (std::getline(ss, item, ',')) {
    const auto eq = item.find('=');
    if (eq == std::string::npos) {
      throw std::invalid_argument("fault spec item '" + item +
                                  "' must be KEY=VALUE (keys: garbage, drop, flip, truncate, dup, "
                                  "swap, nan, disconnect, seed)");
    }
    const std::string key = item.substr(0, eq);
    const std::string value = item.substr(eq + 1);
    if (key == "seed") {
      const double seed = parse_number(item, value);
      if (seed < 0 || seed > 4294967295.0 || seed != std::floor(seed)) {
        throw std::invalid_argument("fault spec item '" + item + "': seed must be an integer in [0, 4294967295]");
      }
      out.seed = static_cast<uint32_t>(seed);
      continue;
    }
    if (key == "disconnect") {
      const auto colon = value.find(':');
      if (colon == std::string::npos) {
        throw std::invalid_argument("fault spec item '" + item + "' must be disconnect=EVERY_S:DOWN_S");
      }
      out.disconnect_every_s = parse_number(item, value.substr(0, colon));
      out.disconnect_down_s = parse_number(item, value.substr(colon + 1));
      if (out.disconnect_every_s <= 0 || out.disconnect_down_s <= 0 ||
          out.disconnect_down_s >= out.disconnect_every_s) {
        throw std::invalid_argument("fault spec item '" + item +
                                    "': need 0 < DOWN_S < EVERY_S (seconds)");
      }
      continue;
    }
    bool found = false;
    for (std::size_t f = 0; f < kFaultCount; ++f) {
      if (key == to_string(static_cast<Fault>(f))) {
        const double p = parse_number(item, value);
        if (p < 0 || p > 1) {
          throw std::invalid_argument("fault spec item '" + item + "': probability must be in [0, 1]");
        }
        out.probability[f] = p;
        total += p;
        found = true;
      }
    }
    if (!found) {
      std::vector<std::string> known;
      for (std::size_t f = 0; f < kFaultCount; ++f) {
        known.emplace_back(to_string(static_cast<Fault>(f)));
      }
      known.insert(known.end(), {"disconnect", "seed"});
      throw std::invalid_argument(unknown_key_message("fault spec", key, known));
    }
  }
  if (total > 1.0) {
    throw std::invalid_argument("fault spec: the line-fault probabilities add up to more than 1");
  }
  return out;
}

bool FaultSpec::any_line_faults() const {
  for (const double p : probability) {
    if (p > 0) return true;
  }
  return false;
}

FaultInjector::FaultInjector(const FaultSpec& spec) : spec_(spec), rng_(spec.seed) {}

std::string FaultInjector::flush() {
  std::string out;
  out.swap(held_);
  return out;
}

std::string FaultInjector::apply(const std::string& line) {
  std::string out = flush();  // a swapped line goes right after its successor
  if (!out.empty()) {
    std::string tmp = line;
    tmp += out;
    out = std::move(tmp);
    return out;  // the successor itself gets no fault (keeps counts exact)
  }
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double x = u(rng_);
  std::size_t chosen = kFaultCount;
  for (std::size_t f = 0; f < kFaultCount; ++f) {
    if (x < spec_.probability[f]) {
      chosen = f;
      break;
    }
    x -= spec_.probability[f];
  }
  if (chosen == kFaultCount) return line;
  const auto star = line.find('*');
  if (line.size() < 8 || line[0] != '$' || star == std::string::npos) return line;  // not ours
  ++counts_[chosen];
  switch (static_cast<Fault>(chosen)) {
    case Fault::kGarbage: {
      std::uniform_int_distribution<int> len(1, 32);
      std::uniform_int_distribution<int> byte(0, 255);
      std::string g;
      const int n = len(rng_);
      while (static_cast<int>(g.size()) < n) {
        const char c = static_cast<char>(byte(rng_));
        if (c != '$' && c != '\n' && c != '\r' && c != ' ' && c != '\t') g += c;
      }
      return g + line;
    }
    case Fault::kDrop:
      return {};
    case Fault::kFlip: {
      std::uniform_int_distribution<std::size_t> pos(1, star - 1);
      std::uniform_int_distribution<int> bit(0, 7);
      std::string l = line;
      for (;;) {
        const std::size_t i = pos(rng_);
        const auto c = static_cast<char>(l[i] ^ static_cast<char>(1 << bit(rng_)));
        if (c != '$' && c != '\n' && c != '\r' && c != '*' && c != ',') {
          l[i] = c;
          return l;
        }
      }
    }
    case Fault::kTruncate: {
      std::uniform_int_distribution<std::size_t> cut(1, line.size() - 3);
      // The tail is lost but the terminator survives, so following noise stays separate.
      return line.substr(0, cut(rng_)) + "\r\n";
    }
    case Fault::kDup:
      return line + line;
    case Fault::kSwap:
      held_ = line;
      return {};
    case Fault::kNan: {
      // Fields: $IMU,seq,t_us,ax,... -> replace ax.
      std::size_t p = 0;
      for (int k = 0; k < 3 && p != std::string::npos; ++k) p = line.find(',', p + 1);
      const std::size_t e = p == std::string::npos ? p : line.find(',', p + 1);
      if (e == std::string::npos) return line;
      const std::string payload =
          line.substr(1, p) + "nan" + line.substr(e, star - e);
      return wrap_payload(payload);
    }
    case Fault::kCount:
      break;
  }
  return line;
}

}  // namespace poise::imu
