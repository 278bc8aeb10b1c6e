#include "poise/eval/north_filter.h"

#include "poise/core/north_yaml.h"
#include "poise/core/yaml_params.h"
#include "poise/eval/runner.h"

#include <algorithm>
#include <stdexcept>

namespace poise::eval {
namespace {

class NorthFilter : public AttitudeFilter, public TrialInputs {
 public:
  NorthFilter(std::unique_ptr<AttitudeFilter> inner, NorthReference north)
      : inner_(std::move(inner)), north_(std::move(north)) {}
  bool update(const ImuSample& sample) override { return inner_->update(sample); }
  [[nodiscard]] Eigen::Quaterniond q_world_body() const override {
    return inner_->initialized() ? north_.to_true(inner_->q_world_body()) : inner_->q_world_body();
  }
  [[nodiscard]] bool initialized() const override { return inner_->initialized(); }
  void reset() override { inner_->reset(); }
  [[nodiscard]] std::map<std::string, uint64_t> rejections() const override { return inner_->rejections(); }
  [[nodiscard]] std::optional<Eigen::Matrix3d> attitude_covariance() const override {
    const std::optional<Eigen::Matrix3d> p = inner_->attitude_covariance();
    return p ? std::optional<Eigen::Matrix3d>(north_.to_true(*p)) : std::nullopt;
  }
  [[nodiscard]] HeadingStatus heading_status() const override { return inner_->heading_status(); }
  [[nodiscard]] SourceReports sources() const override { return inner_->sources(); }
  void begin_trial(const BroadTrial& trial) override {
    if (auto* inputs = dynamic_cast<TrialInputs*>(inner_.get())) {
      inputs->begin_trial(trial);
    }
  }

 private:
  std::unique_ptr<AttitudeFilter> inner_;
  NorthReference north_;
};

}  // namespace

NorthReference north_from_sets(const std::vector<std::string>& sets, const std::string& today,
                               const std::vector<std::string>& also_known) {
  YAML::Node params(YAML::NodeType::Map);
  const std::vector<std::string>& keys = north_param_keys();
  std::string known;
  for (const auto& k : keys) {
    known += (known.empty() ? "" : ", ") + k;
  }
  for (const std::string& set : sets) {
    const size_t eq = set.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw std::invalid_argument("--set " + set + ": expected KEY=VALUE (KEY one of " + known + ")");
    }
    const std::string key = set.substr(0, eq);
    if (std::find(keys.begin(), keys.end(), key) == keys.end()) {
      std::vector<std::string> listed = keys;
      listed.insert(listed.end(), also_known.begin(), also_known.end());
      throw std::invalid_argument(unknown_key_message("--set " + set, key, listed) +
                                  (also_known.empty() ? ": only the north keys" : "") +
                                  "; filter parameters go in the filter's YAML (--config FILE)");
    }
    if (params[key]) {
      throw std::invalid_argument("--set " + set + ": '" + key + "' is given twice");
    }
    try {
      params[key] = parse_yaml(set.substr(eq + 1), "--set " + set);
    } catch (const std::runtime_error& e) {
      throw std::invalid_argument(e.what());
    }
  }
  try {
    return resolve_north(read_north_params(params), today);
  } catch (const std::exception& e) {
    std::string all;
    for (const auto& s : sets) {
      all += (all.empty() ? "" : " ") + s;
    }
    throw std::invalid_argument("--set " + all + ": " + e.what());
  }
}

std::unique_ptr<AttitudeFilter> with_north(std::unique_ptr<AttitudeFilter> filter, const NorthReference& north) {
  if (!north.true_north) {
    return filter;
  }
  filter->seed_field(north.field_ut, north.dip_deg);  // a location: the model's |B| and dip
  return std::make_unique<NorthFilter>(std::move(filter), north);
}

}  // namespace poise::eval
