#include "server/convert/input_map_conversion.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/public/status_macros.h"
#include "server/convert/spec_conversion.h"

namespace nupmpc::server {
namespace {

absl::Status InvalidRule(const std::string& field, const std::string& rule) {
  return absl::InvalidArgumentError(absl::StrCat(field, ": ", rule));
}

// The spec's level entries as one InputLevels per input (count 0: ordinary input).
absl::StatusOr<std::vector<core::InputLevels>> LevelsFromSpec(const v1::ProblemSpec& spec, int L) {
  std::vector<core::InputLevels> levels(L);
  for (int i = 0; i < spec.input_levels_size(); ++i) {
    const v1::InputLevels& e = spec.input_levels(i);
    const std::string field = absl::StrCat("spec.input_levels[", i, "]");
    if (e.input() >= static_cast<unsigned>(L)) {
      return InvalidRule(field + ".input", absl::StrCat(e.input(), " must be < num_inputs = ", L));
    }
    core::InputLevels& v = levels[e.input()];
    if (v.count != 0) return InvalidRule(field + ".input", absl::StrCat("input ", e.input(), " is listed twice"));
    if (e.count() < 2) return InvalidRule(field + ".count", "must be >= 2");
    if (!std::isfinite(e.lowest())) return InvalidRule(field + ".lowest", "must be finite");
    if (!(e.spacing() > 0.0) || !std::isfinite(e.spacing()))
      return InvalidRule(field + ".spacing", "must be finite and > 0");
    const v1::ComponentPrior& own = spec.input_priors(static_cast<int>(e.input()));
    bool weighted = false;
    for (double w : own.weight()) weighted |= w != 0.0;
    if (own.kind() != v1::PRIOR_KIND_UNSPECIFIED || weighted) {
      return InvalidRule(absl::StrCat("spec.input_priors[", e.input(), "]"),
                         "a multi-level input takes no prior of its own (costs go on outputs)");
    }
    v = {.count = static_cast<int>(e.count()), .lowest = e.lowest(), .spacing = e.spacing()};
  }
  return levels;
}

// `values` as L finite numbers (INVALID_ARGUMENT naming `field` otherwise).
absl::Status ReadInputVector(const google::protobuf::RepeatedField<double>& values, int L, const std::string& field,
                             Eigen::VectorXd* out) {
  if (values.size() != L) {
    return InvalidRule(field, absl::StrCat("expected ", L, " values (num_inputs), got ", values.size()));
  }
  for (int i = 0; i < L; ++i) {
    if (!std::isfinite(values[i])) return InvalidRule(absl::StrCat(field, "[", i, "]"), "must be finite");
  }
  *out = Eigen::Map<const Eigen::VectorXd>(values.data(), L);
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<core::InputMap> InputMapFromSpec(const v1::ProblemSpec& spec, const core::Problem& base) {
  const int L = base.num_inputs, N = base.horizon;
  core::InputMap map;
  map.differences = spec.has_input_differences();
  if (spec.input_levels_size() > 0 && map.differences) {
    return InvalidRule("spec.input_differences", "cannot be combined with input_levels yet");
  }
  if (spec.input_levels_size() > 0) {
    NUPMPC_ASSIGN_OR_RETURN(map.levels, LevelsFromSpec(spec, L));
    return map;
  }
  if (!map.differences) return map;

  const v1::InputDifferences& d = spec.input_differences();
  if (d.priors_size() != L) {
    return InvalidRule("spec.input_differences.priors",
                       absl::StrCat("expected ", L, " entries (num_inputs), got ", d.priors_size()));
  }
  map.difference_priors.resize(static_cast<std::size_t>(N) * L);
  for (int l = 0; l < L; ++l) {
    NUPMPC_RETURN_IF_ERROR(ComponentPriorsFromProto(
        d.priors(l), N, absl::StrCat("spec.input_differences.priors[", l, "]"), &map.difference_priors, L, l));
  }
  map.previous_input = Eigen::VectorXd::Zero(L);
  if (d.previous_input_size() != 0) {
    NUPMPC_RETURN_IF_ERROR(
        ReadInputVector(d.previous_input(), L, "spec.input_differences.previous_input", &map.previous_input));
  }
  return map;
}

}  // namespace nupmpc::server
