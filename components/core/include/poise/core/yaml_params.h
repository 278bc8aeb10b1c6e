// Loading Params structs from YAML: every key optional (the C++ defaults apply); unknown keys,
// wrong types and unreadable files are errors naming the file and the key. Header-only; users
// link yaml-cpp themselves (the estimator cores keep it a private dependency).
#pragma once

#include <yaml-cpp/yaml.h>

#include <set>
#include <stdexcept>
#include <string>
#include <utility>

namespace poise {

/// Loads a YAML file; std::runtime_error ("<path>: cannot open the <what>" / "invalid YAML").
inline YAML::Node load_yaml_file(const std::string& path, const std::string& what) {
  try {
    return YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw std::runtime_error(path + ": cannot open the " + what);
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(path + ": invalid YAML: " + e.what());
  }
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
