// Loading Params structs from YAML: every key optional (the C++ defaults apply); unknown keys,
// wrong types and unreadable files are errors naming the file and the key. Header-only; users
// link yaml-cpp themselves (the estimator cores keep it a private dependency).
#pragma once

#include "poise/core/sample_check.h"

#include <yaml-cpp/yaml.h>

#include <cstddef>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>

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

/// Parses YAML text (`source` names it in messages) and applies check_yaml_tree(): every loader
/// (host, filter, driver, camera, intrinsics, tag map, overrides) reads YAML through here or
/// load_yaml_file(). Throws Error "<source>: not valid YAML: ..." on a syntax error.
template <typename Error = std::runtime_error>
YAML::Node parse_yaml(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw Error(source + ": not valid YAML: " + e.what());
  }
  check_yaml_tree<Error>(root, source);
  return root;
}

/// Loads a YAML file; Error ("<path>: cannot open the <what>" / "not valid YAML" / the checks of
/// check_yaml_tree()).
template <typename Error = std::runtime_error>
YAML::Node load_yaml_file(const std::string& path, const std::string& what) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw Error(path + ": cannot open the " + what);
  } catch (const YAML::Exception& e) {
    throw Error(path + ": not valid YAML: " + e.what());
  }
  check_yaml_tree<Error>(root, path);
  return root;
}

/// `use_magnetometer: auto | true | false` (MagnetometerUse, sample_check.h), the same key in every
/// attitude filter's configuration. Anything else throws YAML::Exception "must be auto, true or
/// false (got '...')" (the loaders add the file and the key).
inline MagnetometerUse read_magnetometer_use(const YAML::Node& n) {
  MagnetometerUse u = MagnetometerUse::kAuto;
  if (!n.IsScalar() || !parse_magnetometer_use(n.Scalar(), u)) {
    throw YAML::Exception(n.Mark(), "use_magnetometer must be auto, true or false (got '" +
                                        (n.IsScalar() ? n.Scalar() : YAML::Dump(n)) + "')");
  }
  return u;
}

/// Reads the keys of one YAML mapping into fields, remembering which keys are known so that
/// finish() can reject the others (typos). `reference` names the example file in messages.
class YamlParamReader {
 public:
  YamlParamReader(const YAML::Node& node, std::string path, std::string prefix, std::string reference)
      : node_(node), path_(std::move(path)), prefix_(std::move(prefix)), reference_(std::move(reference)) {
    present_ = node_.IsDefined() && !node_.IsNull();
    if (present_ && !node_.IsMap()) {
      fail(prefix_.empty() ? "the document" : prefix_, "must be a mapping");
    }
  }

  /// Reads `key` into `out` when present; leaves `out` (the default) otherwise.
  template <typename T>
  void get(const std::string& key, T& out) {
    known_.insert(key);
    if (!present_) {
      return;
    }
    const YAML::Node v = static_cast<const YAML::Node&>(node_)[key];
    if (!v.IsDefined() || v.IsNull()) {
      return;
    }
    try {
      out = v.as<T>();
    } catch (const YAML::Exception&) {
      fail(name(key), "has the wrong type");
    }
  }

  /// The reader of a nested mapping `key` (absent: a reader that reads nothing).
  YamlParamReader child(const std::string& key) {
    known_.insert(key);
    const YAML::Node sub = present_ ? static_cast<const YAML::Node&>(node_)[key] : YAML::Node();
    return YamlParamReader(sub, path_, name(key), reference_);
  }

  /// Rejects keys that no get()/child() asked for.
  void finish() const {
    if (!present_) {
      return;
    }
    for (const auto& kv : node_) {
      const auto key = kv.first.as<std::string>();
      if (known_.count(key) == 0) {
        fail(name(key), "is not a known key (check the spelling against " + reference_ + ")");
      }
    }
  }

  [[noreturn]] void fail(const std::string& key, const std::string& what) const {
    throw std::runtime_error(path_ + ": " + key + " " + what);
  }
  [[nodiscard]] std::string name(const std::string& key) const {
    return prefix_.empty() ? key : prefix_ + "." + key;
  }

 private:
  YAML::Node node_;
  std::string path_;
  std::string prefix_;
  std::string reference_;
  std::set<std::string> known_;
  bool present_ = false;
};

}  // namespace poise
