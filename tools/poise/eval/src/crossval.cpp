#include "poise/eval/crossval.h"

#include "poise/core/yaml_params.h"

#include <yaml-cpp/yaml.h>

#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>

namespace poise::eval {
namespace {

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string cur;
  std::istringstream is(s);
  while (std::getline(is, cur, sep)) {
    out.push_back(cur);
  }
  if (!s.empty() && s.back() == sep) {
    out.emplace_back();
  }
  return out;
}

}  // namespace

std::vector<GridAxis> parse_grid(const std::vector<std::string>& specs, size_t max_points) {
  std::vector<GridAxis> axes;
  std::set<std::string> keys;
  size_t points = 1;
  for (const auto& spec : specs) {
    const auto eq = spec.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 >= spec.size()) {
      throw std::invalid_argument("grid '" + spec + "': expected key=value1,value2,...");
    }
    GridAxis a;
    a.key = spec.substr(0, eq);
    if (!keys.insert(a.key).second) {
      throw std::invalid_argument("grid '" + spec + "': key '" + a.key + "' given twice");
    }
    for (const auto& v : split(spec.substr(eq + 1), ',')) {
      if (v.empty()) {
        throw std::invalid_argument("grid '" + spec + "': empty value");
      }
      a.values.push_back(v);
    }
    points *= a.values.size();
    if (points > max_points) {
      throw std::invalid_argument("grid has more than " + std::to_string(max_points) + " candidates");
    }
    axes.push_back(std::move(a));
  }
  return axes;
}

std::vector<Overrides> grid_points(const std::vector<GridAxis>& axes) {
  std::vector<Overrides> pts{Overrides{}};
  for (const auto& a : axes) {
    std::vector<Overrides> next;
    for (const auto& p : pts) {
      for (const auto& v : a.values) {
        Overrides o = p;
        o.emplace_back(a.key, v);
        next.push_back(std::move(o));
      }
    }
    pts = std::move(next);
  }
  return pts;
}

std::string describe(const Overrides& o) {
  std::string s;
  for (const auto& [k, v] : o) {
    s += (s.empty() ? "" : " ") + k + "=" + v;
  }
  return s.empty() ? "(base configuration)" : s;
}

void write_config_with_overrides(const std::string& base_yaml_path, const Overrides& overrides,
                                 const std::string& out_path, const std::string& header_comment) {
  YAML::Node root(YAML::NodeType::Map);
  if (!base_yaml_path.empty()) {
    try {
      root = load_yaml_file(base_yaml_path, "base configuration");
    } catch (const std::exception& e) {
      throw std::runtime_error("cannot read '" + base_yaml_path + "': " + e.what());
    }
    if (!root.IsMap()) {
      throw std::runtime_error(base_yaml_path + ": expected a YAML map");
    }
  }
  // yaml-cpp: `a = b` on nodes writes b into a's node; reset() rebinds the handle.
  YAML::Node section;
  section.reset(root);
  if (root.size() == 1 && root.begin()->second.IsMap()) {
    section.reset(root.begin()->second);
  }
  for (const auto& [key, value] : overrides) {
    const auto parts = split(key, '.');
    YAML::Node node;
    node.reset(section);
    for (size_t i = 0; i + 1 < parts.size(); ++i) {
      if (!node[parts[i]] || !node[parts[i]].IsMap()) {
        node[parts[i]] = YAML::Node(YAML::NodeType::Map);
      }
      YAML::Node child = node[parts[i]];
      node.reset(child);
    }
    try {
      node[parts.back()] = parse_yaml(value, "grid value for '" + key + "'");
    } catch (const std::runtime_error& e) {
      throw std::runtime_error("grid value '" + value + "' for '" + key + "' is not YAML: " + e.what());
    }
  }
  std::ofstream f(out_path);
  if (!f) {
    throw std::runtime_error("cannot write '" + out_path + "'");
  }
  if (!header_comment.empty()) {
    for (const auto& line : split(header_comment, '\n')) {
      f << "# " << line << "\n";
    }
  }
  f << root << "\n";
  f.close();  // flushes: a full disk shows here, not in a destructor that cannot report it
  if (!f) {
    throw std::runtime_error("error while writing '" + out_path + "' (disk full or device refused the data)");
  }
}

double choice_objective(const std::vector<TrialResult>& results) {
  const GroupMeans g = group_means(results);
  if (g.n_undisturbed > 0 && g.n_disturbed > 0) {
    return 0.5 * (g.undisturbed.total_deg + g.disturbed.total_deg);
  }
  return g.n_undisturbed > 0 ? g.undisturbed.total_deg : g.disturbed.total_deg;
}

CrossValidation cross_validate(const std::vector<std::vector<TrialResult>>& by_candidate, int folds) {
  if (by_candidate.empty() || by_candidate.front().empty()) {
    throw std::invalid_argument("cross-validation needs at least one candidate and one trial");
  }
  const size_t n = by_candidate.front().size();
  for (const auto& c : by_candidate) {
    if (c.size() != n) {
      throw std::invalid_argument("cross-validation: every candidate must have the same trials");
    }
  }
  const int k = folds == 0 ? static_cast<int>(n) : folds;
  if (n >= 2 && (k < 2 || k > static_cast<int>(n))) {
    throw std::invalid_argument("folds must be in [2, " + std::to_string(n) + "] (0 = leave one trial out)");
  }
  auto best_on = [&](const std::vector<bool>& use) {
    size_t best = 0;
    double best_v = std::numeric_limits<double>::infinity();
    for (size_t c = 0; c < by_candidate.size(); ++c) {
      std::vector<TrialResult> sub;
      for (size_t t = 0; t < n; ++t) {
        if (use[t]) {
          sub.push_back(by_candidate[c][t]);
        }
      }
      const double v = choice_objective(sub);
      if (v < best_v) {  // strict: ties keep the lower index
        best_v = v;
        best = c;
      }
    }
    return best;
  };
  CrossValidation cv;
  cv.folds = n >= 2 ? k : 1;
  cv.in_sample_choice = best_on(std::vector<bool>(n, true));
  cv.in_sample = by_candidate[cv.in_sample_choice];
  cv.cross_validated.resize(n);
  cv.choice_per_trial.resize(n);
  if (n < 2) {  // nothing to hold out: the in-sample figure is all there is
    cv.cross_validated = cv.in_sample;
    cv.choice_per_trial.assign(n, cv.in_sample_choice);
    return cv;
  }
  for (int f = 0; f < k; ++f) {
    std::vector<bool> train(n);
    for (size_t t = 0; t < n; ++t) {
      train[t] = static_cast<int>(t % static_cast<size_t>(k)) != f;
    }
    const size_t c = best_on(train);
    for (size_t t = 0; t < n; ++t) {
      if (!train[t]) {
        cv.cross_validated[t] = by_candidate[c][t];
        cv.choice_per_trial[t] = c;
      }
    }
  }
  return cv;
}

}  // namespace poise::eval
