// Loading Params structs from YAML: every key optional (the C++ defaults apply); unknown keys,
// wrong types and unreadable files are errors naming the file and the key. The one shape of a
// loader (YamlParamReader) and the one unknown-key check (check_known_keys / unknown_key_message)
// of every loader in poise. Header-only; users link yaml-cpp themselves (the estimator cores keep
// it a private dependency).
#pragma once

#include "poise/core/params_check.h"
#include "poise/core/sample_check.h"

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/parser.h>
#include <yaml-cpp/yaml.h>

#include <sys/stat.h>

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <fstream>
#include <initializer_list>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace poise {

/// What every YAML document poise reads must pass beyond the syntax (yaml-cpp accepts both and
/// then silently uses one): no mapping key given twice, and no plain scalar that YAML reads as
/// a non-finite number (.inf, -.inf, .nan: no parameter means "infinite"; quote it for a
/// string). Throws std::runtime_error "<source>:<line>: ..." naming the key path. `at` is the
/// path of `node` ("" for the document). `Error` is the exception type thrown (a loader's own
/// configuration error type, constructible from a string).
template <typename Error = std::runtime_error>
void check_yaml_tree(const YAML::Node& node, const std::string& source, const std::string& at = "") {
  auto line = [](const YAML::Node& n) { return std::to_string(n.Mark().line + 1); };
  auto where = [&](const YAML::Node& n) { return source + ":" + line(n) + ": "; };
  if (node.IsMap()) {
    std::map<std::string, YAML::Node> seen;
    for (const auto& kv : node) {
      const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : YAML::Dump(kv.first);
      const std::string path = at.empty() ? key : at + "." + key;
      const auto [it, fresh] = seen.emplace(key, kv.first);
      if (!fresh) {
        throw Error(where(kv.first) + "key '" + path + "' is given twice (first on line " +
                                 line(it->second) + "); remove one");
      }
      check_yaml_tree<Error>(kv.second, source, path);
    }
  } else if (node.IsSequence()) {
    for (std::size_t i = 0; i < node.size(); ++i) {
      check_yaml_tree<Error>(node[i], source, at + "[" + std::to_string(i) + "]");
    }
  } else if (node.IsScalar() && node.Tag() == "?") {  // plain (unquoted) scalar
    std::string v = node.Scalar();
    if (!v.empty() && (v[0] == '+' || v[0] == '-')) {
      v.erase(0, 1);
    }
    for (const char* bad : {".inf", ".Inf", ".INF", ".nan", ".NaN", ".NAN"}) {
      if (v == bad) {
        throw Error(where(node) + "'" + (at.empty() ? std::string("the document") : at) +
                                 "' is " + node.Scalar() + ": values must be finite numbers");
      }
    }
  }
}

/// Bounds on every YAML document poise reads (docs/DEVELOPING.md "Loading configuration"): a
/// configuration file is a few kilobytes; these stop a hostile one before it costs memory or time.
inline constexpr std::size_t kMaxYamlBytes = std::size_t{1} << 20;  ///< 1 MiB of text
inline constexpr int kMaxYamlDepth = 32;                            ///< nested sequences / mappings

/// The parser's events checked before any node is built: no alias (`*name`: a shared or cyclic
/// node, the alias bomb and the self-reference `&c [ {params: *c} ]`), no nesting deeper than
/// kMaxYamlDepth. Throws Error "<source>:<line>: ...".
template <typename Error>
class YamlBoundsCheck : public YAML::EventHandler {
 public:
  YamlBoundsCheck(const std::string& text, const std::string& source) : text_(text), source_(source) {}

  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t, const std::string&) override {}
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t) override {
    std::string name;
    if (mark.pos >= 0 && static_cast<std::size_t>(mark.pos) < text_.size()) {
      const std::size_t end = text_.find_first_of(" \t\r\n,]}", static_cast<std::size_t>(mark.pos));
      name = text_.substr(static_cast<std::size_t>(mark.pos), end == std::string::npos ? std::string::npos
                                                                                        : end - mark.pos);
    }
    throw Error(where(mark) + "the alias " + (name.empty() ? std::string("*") : name) +
                " is not accepted: poise reads no YAML anchors or aliases (&name / *name); write the value out");
  }
  void OnSequenceStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {
    enter(mark);
  }
  void OnSequenceEnd() override { --depth_; }
  void OnMapStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {
    enter(mark);
  }
  void OnMapEnd() override { --depth_; }

 private:
  [[nodiscard]] std::string where(const YAML::Mark& mark) const {
    return source_ + ":" + std::to_string(mark.line + 1) + ": ";
  }
  void enter(const YAML::Mark& mark) {
    if (++depth_ > kMaxYamlDepth) {
      throw Error(where(mark) + "nested more than " + std::to_string(kMaxYamlDepth) +
                  " levels deep: not a poise configuration");
    }
  }
  const std::string& text_;
  const std::string& source_;
  int depth_ = 0;
};

/// Parses YAML text (`source` names it in messages) and applies check_yaml_tree(): every loader
/// (host, filter, driver, camera, intrinsics, tag map, overrides, --set, --grid) reads YAML through
/// here or load_yaml_file(). Refused before a node is built: more than kMaxYamlBytes of text
/// ("<source>: N bytes: more than the 1048576 a configuration may hold"), an alias and nesting
/// deeper than kMaxYamlDepth (YamlBoundsCheck). Throws Error "<source>: not valid YAML: ..." on a
/// syntax error. Only the first document is read.
template <typename Error = std::runtime_error>
YAML::Node parse_yaml(const std::string& text, const std::string& source) {
  if (text.size() > kMaxYamlBytes) {
    throw Error(source + ": " + std::to_string(text.size()) + " bytes: more than the " +
                std::to_string(kMaxYamlBytes) + " a configuration may hold");
  }
  YAML::Node root;
  try {
    std::istringstream in(text);
    YAML::Parser parser(in);
    YamlBoundsCheck<Error> bounds(text, source);
    parser.HandleNextDocument(bounds);
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw Error(source + ": not valid YAML: " + e.what());
  }
  check_yaml_tree<Error>(root, source);
  return root;
}

/// The text of a configuration file, read only when it is a regular file of at most kMaxYamlBytes
/// (a FIFO would block, /dev/zero never ends). Error(`cannot_open`) when it cannot be opened,
/// "<path>: not a regular file (a FIFO, device or directory): give a YAML file" and
/// "<path>: N bytes: more than the 1048576 a configuration may hold".
template <typename Error = std::runtime_error>
std::string read_yaml_text(const std::string& path, const std::string& cannot_open) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    throw Error(cannot_open);
  }
  if (!S_ISREG(st.st_mode)) {
    throw Error(path + ": not a regular file (a FIFO, device or directory): give a YAML file");
  }
  if (static_cast<unsigned long long>(st.st_size) > kMaxYamlBytes) {
    throw Error(path + ": " + std::to_string(st.st_size) + " bytes: more than the " +
                std::to_string(kMaxYamlBytes) + " a configuration may hold");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw Error(cannot_open);
  }
  std::string text(kMaxYamlBytes + 1, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));
  return text;  // a file grown past the limit since stat() is refused by parse_yaml()
}

/// Loads a YAML file; Error ("<path>: cannot open the <what>" / read_yaml_text() / parse_yaml()).
template <typename Error = std::runtime_error>
YAML::Node load_yaml_file(const std::string& path, const std::string& what) {
  return parse_yaml<Error>(read_yaml_text<Error>(path, path + ": cannot open the " + what), path);
}

/// The one message for a key that nothing reads, in every loader (filter, driver and camera files,
/// host files, component parameters):
///   "<where>: unknown key '<key>' (known: <k1>, <k2>, ...)"
/// `where` names the file or the component, `key` is spelled as in the YAML (dotted below the
/// document: `limits.max_dt_s`), `known` lists what is allowed at that place.
inline std::string unknown_key_message(const std::string& where, const std::string& key,
                                       const std::vector<std::string>& known) {
  std::string list;
  for (const auto& k : known) {
    list += (list.empty() ? "" : ", ") + k;
  }
  return where + ": unknown key '" + key + "' (known: " + list + ")";
}

/// The text of a mapping key (a key that is itself a collection is dumped, so it can be named).
inline std::string yaml_key_text(const YAML::Node& key) {
  return key.IsScalar() ? key.Scalar() : YAML::Dump(key);
}

/// Refuses the first key of the mapping `node` that `known` does not hold, with
/// Error(unknown_key_message(where, prefix + key, known)). An absent or null node has no keys; any
/// other node that is not a mapping is Error("<where>: <prefix> must be a mapping"). `prefix` is
/// the section's dotted path with its trailing dot ("limits."), "" for the document.
template <typename Error = std::runtime_error>
void check_known_keys(const YAML::Node& node, const std::vector<std::string>& known, const std::string& where,
                      const std::string& prefix = "") {
  if (!node.IsDefined() || node.IsNull()) {
    return;
  }
  if (!node.IsMap()) {
    const std::string section = prefix.empty() ? "the document" : prefix.substr(0, prefix.size() - 1);
    throw Error(where + ": " + section + " must be a mapping");
  }
  for (const auto& kv : node) {
    const std::string key = yaml_key_text(kv.first);
    if (std::find(known.begin(), known.end(), key) == known.end()) {
      throw Error(unknown_key_message(where, prefix + key, known));
    }
  }
}

/// The one shape of loading a YAML mapping into a Params / config struct whose fields hold the
/// defaults (docs/DEVELOPING.md "Loading configuration"):
///   YamlParamReader r(root, path);          // or a section: r.child("limits")
///   r.get("max_dt_s", p.max_dt_s);           // optional: absent keeps the default, null is refused
///   r.finish();                              // every key nothing asked for: unknown_key_message()
///   validate_loaded(p, path);                // ranges: Params::validate() (ParamCheck)
/// The known keys are the ones the code reads (no list to keep in step). A key `a.b: v` is the
/// same as `a: {b: v}` (the spelling of `--set` and `--grid`); both at once is an error. Wrong
/// types and bad values are Error("<path>: <dotted key> <what>").
template <typename Error = std::runtime_error>
class BasicYamlParamReader {
 public:
  /// `node`: the mapping (absent or null: nothing given); `path`: the file or component named in
  /// messages; `prefix`: the section's dotted name ("" for the document).
  BasicYamlParamReader(const YAML::Node& node, std::string path, std::string prefix = "")
      : path_(std::move(path)), prefix_(std::move(prefix)) {
    present_ = node.IsDefined() && !node.IsNull();
    if (present_ && !node.IsMap()) {
      fail_at(prefix_.empty() ? "the document" : prefix_, "must be a mapping");
    }
    node_ = present_ ? nest_dotted(node) : YAML::Node();
  }

  /// Reads `key` into `out` when given; keeps `out` (the default) when absent; refuses null. T: bool,
  /// integers, floating point, std::string, std::vector<double>, fixed-size Eigen matrices of
  /// double (a list of numbers; a matrix: a list of rows).
  template <typename T>
  void get(const std::string& key, T& out) {
    const YAML::Node v = value(key);
    if (!v) {
      return;
    }
    if constexpr (is_eigen_matrix<T>::value) {
      read_matrix(key, v, out);
    } else {
      try {
        out = v.as<T>();
      } catch (const YAML::Exception&) {
        fail(key, expected<T>());
      }
    }
  }
  /// get(), then the value must be finite (for floating point) and within [lo, hi]:
  /// "<key> must be in [lo, hi], got v" (for a matrix, every element, named key[i] or key[r][c]).
  template <typename T, typename Bound>
  void get_in(const std::string& key, T& out, Bound lo, Bound hi) {
    T v = out;
    get(key, v);
    if constexpr (is_eigen_matrix<T>::value) {
      for (Eigen::Index r = 0; r < v.rows(); ++r) {
        for (Eigen::Index c = 0; c < v.cols(); ++c) {
          const std::string at = T::ColsAtCompileTime == 1
                                     ? "[" + std::to_string(r) + "]"
                                     : "[" + std::to_string(r) + "][" + std::to_string(c) + "]";
          check_range(key + at, v(r, c), lo, hi);
        }
      }
    } else {
      check_range(key, v, lo, hi);
    }
    out = v;
  }
  /// A number given in the file's unit (the key's suffix, e.g. `_ms`, `_deg`): when given,
  /// out = value * scale (e.g. 1e-3 for ms -> s); absent keeps the default untouched.
  void get_scaled(const std::string& key, double& out, double scale) {
    if (given(key)) {
      double v = 0.0;
      get(key, v);
      out = v * scale;
    }
  }
  /// A floating-point key whose null (`~`) means NaN ("not configured: learn it"); absent keeps
  /// the default.
  void get_nullable(const std::string& key, double& out) {
    const YAML::Node v = raw(key);
    if (v && v.IsNull()) {
      out = std::nan("");
      return;
    }
    get(key, out);
  }
  /// A key read by `parse(const YAML::Node&)` (an enum, a quaternion, ...), called when the key is
  /// given; an exception it throws (YAML or std) becomes "<path>: <key> <its message>".
  template <typename Parse>
  void get_with(const std::string& key, Parse&& parse) {
    const YAML::Node v = value(key);
    if (!v) {
      return;
    }
    try {
      parse(v);
    } catch (const YAML::Exception& e) {
      fail(key, e.msg);
    } catch (const std::exception& e) {
      fail(key, e.what());
    }
  }
  /// A key naming one of the values of an enum: "must be one of <names> (got '...')" otherwise.
  template <typename Enum>
  void get_enum(const std::string& key, Enum& out, const std::vector<std::pair<std::string, Enum>>& names) {
    get_with(key, [&](const YAML::Node& n) {
      std::string list;
      for (const auto& [name, value] : names) {
        if (n.IsScalar() && n.Scalar() == name) {
          out = value;
          return;
        }
        list += (list.empty() ? "" : ", ") + name;
      }
      throw std::invalid_argument("must be one of " + list + " (got '" + (n.IsScalar() ? n.Scalar() : YAML::Dump(n)) +
                                  "')");
    });
  }
  /// The same, each value spelled as its to_string() (found by argument-dependent lookup).
  template <typename Enum>
  void get_enum(const std::string& key, Enum& out, std::initializer_list<Enum> values) {
    std::vector<std::pair<std::string, Enum>> names;
    for (const Enum e : values) {
      names.emplace_back(to_string(e), e);
    }
    get_enum(key, out, names);
  }
  /// True when `key` is given (a null value is refused, as by get()). Marks it known.
  [[nodiscard]] bool given(const std::string& key) { return static_cast<bool>(value(key)); }
  /// True when the mapping holds `key` (null included). Marks it known.
  [[nodiscard]] bool has(const std::string& key) {
    const bool in_map = raw(key).IsDefined();
    return present_ && in_map;
  }

  /// The reader of the nested mapping `key` (absent: a reader that reads nothing).
  [[nodiscard]] BasicYamlParamReader child(const std::string& key) {
    return BasicYamlParamReader(raw(key), path_, name(key));
  }

  /// Refuses the keys that nothing asked for: unknown_key_message() naming the file, the dotted
  /// key and the keys read at this level.
  void finish() const {
    if (!present_) {
      return;
    }
    for (const auto& kv : node_) {
      const std::string key = yaml_key_text(kv.first);
      if (std::find(known_.begin(), known_.end(), key) == known_.end()) {
        throw Error(unknown_key_message(path_, name(key), known_));
      }
    }
  }

  /// Throws Error("<path>: <dotted key> <what>").
  [[noreturn]] void fail(const std::string& key, const std::string& what) const { fail_at(name(key), what); }
  [[nodiscard]] std::string name(const std::string& key) const {
    return prefix_.empty() ? key : prefix_ + "." + key;
  }
  [[nodiscard]] const std::string& path() const { return path_; }

 private:
  template <typename T>
  struct is_eigen_matrix : std::false_type {};
  template <int R, int C, int O, int MR, int MC>
  struct is_eigen_matrix<Eigen::Matrix<double, R, C, O, MR, MC>> : std::true_type {};

  template <typename T>
  static std::string expected() {
    if constexpr (std::is_same_v<T, bool>) {
      return "must be true or false";
    } else if constexpr (std::is_integral_v<T>) {
      return "must be an integer";
    } else if constexpr (std::is_floating_point_v<T>) {
      return "must be a number";
    } else if constexpr (std::is_same_v<T, std::string>) {
      return "must be a string";
    } else if constexpr (std::is_same_v<T, std::vector<double>>) {
      return "must be a list of numbers";
    } else {
      return "has the wrong type";
    }
  }

  [[noreturn]] void fail_at(const std::string& dotted, const std::string& what) const {
    throw Error(path_ + ": " + dotted + " " + what);
  }

  template <typename V, typename Bound>
  void check_range(const std::string& key, V v, Bound lo, Bound hi) const {
    bool ok = v >= static_cast<V>(lo) && v <= static_cast<V>(hi);
    if constexpr (std::is_floating_point_v<V>) {
      ok = ok && std::isfinite(v);
    }
    if (!ok) {
      std::ostringstream m;
      m << "must be in [" << lo << ", " << hi << "], got " << v;
      fail(key, m.str());
    }
  }

  template <typename M>
  void read_matrix(const std::string& key, const YAML::Node& v, M& out) const {
    constexpr int kRows = M::RowsAtCompileTime;
    constexpr int kCols = M::ColsAtCompileTime;
    static_assert(kRows > 0 && kCols > 0, "fixed-size matrices only");
    const std::string shape = kCols == 1 ? "must be a list of " + std::to_string(kRows) + " numbers"
                                         : "must be " + std::to_string(kRows) + " rows of " +
                                               std::to_string(kCols) + " numbers";
    if (!v.IsSequence() || v.size() != static_cast<std::size_t>(kRows)) {
      fail(key, shape);
    }
    M m;
    try {
      for (int r = 0; r < kRows; ++r) {
        const YAML::Node row = v[static_cast<std::size_t>(r)];
        if (kCols == 1) {
          m(r, 0) = row.as<double>();
          continue;
        }
        if (!row.IsSequence() || row.size() != static_cast<std::size_t>(kCols)) {
          fail(key, shape);
        }
        for (int c = 0; c < kCols; ++c) {
          m(r, c) = row[static_cast<std::size_t>(c)].as<double>();
        }
      }
    } catch (const YAML::Exception&) {
      fail(key, shape);
    }
    out = m;
  }

  /// The node of `key` as given (null included); marks the key known.
  YAML::Node raw(const std::string& key) {
    if (std::find(known_.begin(), known_.end(), key) == known_.end()) {
      known_.push_back(key);
    }
    return present_ ? static_cast<const YAML::Node&>(node_)[key] : YAML::Node(YAML::NodeType::Undefined);
  }
  /// The node of `key` when given, else an undefined node. A null value (`key:` or `key: ~`) is
  /// refused: it would look like a value and silently keep the default (get_nullable() alone gives
  /// null a meaning).
  YAML::Node value(const std::string& key) {
    const YAML::Node v = raw(key);
    if (v.IsDefined() && v.IsNull()) {
      fail(key, "has no value (empty or ~): give one, or leave the key out for the default");
    }
    return v;
  }

  /// A copy of `map` with every dotted key `a.b: v` moved under `a: {b: v}` (the document itself
  /// is not changed).
  YAML::Node nest_dotted(const YAML::Node& map) const {
    bool dotted = false;
    for (const auto& kv : map) {
      dotted = dotted || (kv.first.IsScalar() && kv.first.Scalar().find('.') != std::string::npos);
    }
    if (!dotted) {
      return map;
    }
    YAML::Node out(YAML::NodeType::Map);
    const auto given = [&out](const std::string& k) { return static_cast<bool>(std::as_const(out)[k]); };
    for (const auto& kv : map) {
      const std::string key = yaml_key_text(kv.first);
      const auto dot = kv.first.IsScalar() ? key.find('.') : std::string::npos;
      if (dot == std::string::npos) {
        if (given(key)) {
          fail_at(name(key), "is given twice (as a section and as dotted keys)");
        }
        out[key] = YAML::Clone(kv.second);
        continue;
      }
      const std::string head = key.substr(0, dot);
      if (!given(head)) {
        out[head] = YAML::Node(YAML::NodeType::Map);
      } else if (!std::as_const(out)[head].IsMap()) {
        fail_at(name(head), "is given twice (as a value and as dotted keys)");
      }
      YAML::Node section = out[head];
      const std::string rest = key.substr(dot + 1);
      if (static_cast<bool>(std::as_const(section)[rest])) {
        fail_at(name(key), "is given twice");
      }
      section[rest] = YAML::Clone(kv.second);
    }
    return out;
  }

  YAML::Node node_;
  std::string path_;
  std::string prefix_;
  std::vector<std::string> known_;  ///< in the order read (the list in messages)
  bool present_ = false;
};

using YamlParamReader = BasicYamlParamReader<>;

/// `use_magnetometer: auto | true | false` (MagnetometerUse, sample_check.h), the same key in every
/// attitude filter's configuration.
template <typename Error>
void read_magnetometer_use(BasicYamlParamReader<Error>& r, MagnetometerUse& out) {
  r.get_with("use_magnetometer", [&out](const YAML::Node& n) {
    if (!n.IsScalar() || !parse_magnetometer_use(n.Scalar(), out)) {
      throw std::invalid_argument("must be auto, true or false (got '" + (n.IsScalar() ? n.Scalar() : YAML::Dump(n)) +
                                  "')");
    }
  });
}

/// A `limits:` section (SampleLimits; the keys validate(SampleLimits, check) names, limits.*).
template <typename Error>
void read_sample_limits(BasicYamlParamReader<Error>& r, SampleLimits& l) {
  BasicYamlParamReader<Error> limits = r.child("limits");
  limits.get("min_accel_norm_mps2", l.min_accel_norm_mps2);
  limits.get("min_mag_norm_ut", l.min_mag_norm_ut);
  limits.get("max_gyro_rps", l.max_gyro_rps);
  limits.get("max_accel_mps2", l.max_accel_mps2);
  limits.get("max_mag_ut", l.max_mag_ut);
  limits.get("max_dt_s", l.max_dt_s);
  limits.finish();
}

/// The one loader of an estimator's parameter file: load_yaml_file() (syntax, duplicate keys,
/// non-finite numbers; `what` names the file in its messages), then the mapping under `section`
/// when the document has that key (it must then be the only one; "" = none) or else the document
/// itself, `read(reader, params)` into `params` (the struct defaults or a preset), finish() at
/// both levels (unknown keys) and validate_loaded() (ranges: Params::validate()). Throws
/// std::runtime_error naming the file and the key.
template <typename Params, typename Read>
Params load_params_file(const std::string& path, const std::string& what, const std::string& section,
                        Params params, Read&& read) {
  const YAML::Node root = load_yaml_file(path, what);
  YamlParamReader doc(root, path);
  if (!section.empty() && doc.has(section)) {
    YamlParamReader r = doc.child(section);
    read(r, params);
    r.finish();
  } else {
    read(doc, params);
  }
  doc.finish();
  validate_loaded(params, path);
  return params;
}

}  // namespace poise
