#include "client/nonlinear_session_rules.h"

#include <cmath>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/status_macros.h"

namespace nupmpc::nonlinear_internal {
namespace {

absl::Status CheckPerComponent(const std::vector<double>& values, std::size_t size, const char* field,
                               const char* component) {
  if (values.empty()) return absl::OkStatus();
  if (values.size() != size) {
    return absl::InvalidArgumentError(absl::StrCat("NonlinearSessionOptions.region.", field, ": expected ", size,
                                                   " values (one per ", component, "), got ", values.size()));
  }
  for (std::size_t i = 0; i < size; ++i) {
    if (!(values[i] > 0.0)) {
      return absl::InvalidArgumentError(absl::StrCat("NonlinearSessionOptions.region.", field, "[", i,
                                                     "] = ", values[i], ": must be > 0 (Infinity for none)"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ValidateOptions(const NonlinearSessionOptions& o, const NonlinearModel& m) {
  const auto invalid = [](const std::string& what) {
    return absl::InvalidArgumentError("NonlinearSessionOptions." + what);
  };
  if (o.max_linearisations < 1) {
    return invalid(absl::StrCat("max_linearisations = ", o.max_linearisations, ": must be ≥ 1"));
  }
  if (!(o.step_tolerance > 0.0) || !std::isfinite(o.step_tolerance)) {
    return invalid(absl::StrCat("step_tolerance = ", o.step_tolerance, ": must be finite and > 0"));
  }
  if (!v1::WarmStart_IsValid(o.warm_start)) return invalid(absl::StrCat("warm_start = ", o.warm_start, ": unknown"));
  if (!(o.jacobian_tolerance > 0.0) || !std::isfinite(o.jacobian_tolerance)) {
    return invalid(absl::StrCat("jacobian_tolerance = ", o.jacobian_tolerance, ": must be finite and > 0"));
  }
  if (!(o.finite_difference_step > 0.0 && o.finite_difference_step < 1.0)) {
    return invalid(absl::StrCat("finite_difference_step = ", o.finite_difference_step, ": must be in (0, 1)"));
  }
  NUPMPC_CLIENT_RETURN_IF_ERROR(CheckPerComponent(o.region.state_radius, m.num_states, "state_radius", "state"));
  NUPMPC_CLIENT_RETURN_IF_ERROR(
      CheckPerComponent(o.region.state_proximal_stddev, m.num_states, "state_proximal_stddev", "state"));
  NUPMPC_CLIENT_RETURN_IF_ERROR(
      CheckPerComponent(o.region.input_proximal_stddev, m.num_inputs, "input_proximal_stddev", "input"));
  if (const std::optional<StepControlError> bad = o.step_control.FirstInvalid(); bad.has_value()) {
    return invalid(absl::StrCat("step_control.", bad->field, " = ", bad->value, ": ", bad->requirement));
  }
  return absl::OkStatus();
}

absl::Status ValidateSpec(const v1::ProblemSpec& spec, const NonlinearModel& m) {
  const auto invalid = [](const std::string& what) { return absl::InvalidArgumentError("spec." + what); };
  if (spec.has_gp()) return invalid("gp: a GP session has its own model; NonlinearSession needs a plain spec");
  if (spec.input_levels_size() > 0 || spec.has_input_differences()) {
    return invalid(absl::StrCat(spec.input_levels_size() > 0 ? "input_levels" : "input_differences",
                                ": the server takes no model update for such sessions"));
  }
  const v1::Model& model = spec.model();
  if (model.horizon() < 1) return invalid("model.horizon: required (≥ 1)");
  for (const auto& [field, given, wanted] : {std::tuple{"num_states", model.num_states(), m.num_states},
                                             {"num_inputs", model.num_inputs(), m.num_inputs},
                                             {"num_outputs", model.num_outputs(), m.num_outputs}}) {
    if (given != 0 && given != static_cast<unsigned>(wanted)) {
      return invalid(absl::StrCat("model.", field, " = ", given, ": does not match the NonlinearModel's ", wanted,
                                  " (leave it 0)"));
    }
  }
  if (model.a_size() > 0 || model.b_size() > 0 || model.c_size() > 0 || model.state_offset_size() > 0 ||
      model.output_offset_size() > 0) {
    return invalid(
        "model: a, b, c, state_offset and output_offset must be empty (NonlinearSession linearises the "
        "NonlinearModel into them)");
  }
  if (spec.initial_state().mean_size() != m.num_states) {
    return invalid(absl::StrCat("initial_state.mean: expected ", m.num_states, " values (num_states), got ",
                                spec.initial_state().mean_size()));
  }
  if (spec.output_priors_size() != m.num_outputs) {
    return invalid(absl::StrCat("output_priors: expected ", m.num_outputs, " entries (one per model output), got ",
                                spec.output_priors_size()));
  }
  if (spec.has_keep_out()) {
    for (const auto& [field, index] : {std::pair{"first_output", spec.keep_out().first_output()},
                                       {"second_output", spec.keep_out().second_output()}}) {
      if (index >= static_cast<unsigned>(m.num_outputs)) {
        return invalid(absl::StrCat("keep_out.", field, " = ", index, ": must name one of the model's ", m.num_outputs,
                                    " outputs"));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace nupmpc::nonlinear_internal
