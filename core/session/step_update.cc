#include "core/session/step_update.h"

#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

absl::Status CheckComponents(const std::vector<ComponentPriors>& components, const char* field, const char* count_name,
                             int count, int steps) {
  for (std::size_t i = 0; i < components.size(); ++i) {
    const ComponentPriors& c = components[i];
    const std::string path = absl::StrCat(field, "[", i, "]");
    if (c.index < 0 || c.index >= count) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ".index = ", c.index, ": must be < ", count_name, " = ", count));
    }
    if (static_cast<int>(c.priors.size()) != steps) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ".prior: expected ", steps, " steps, got ", c.priors.size()));
    }
    const std::string prior_field = path + ".prior";
    for (int n = 0; n < steps; ++n) {
      NUPMPC_RETURN_IF_ERROR(ValidatePrior(c.priors[n], prior_field.c_str(), n));
    }
  }
  return absl::OkStatus();
}

// Row n+1 of a step-major array of `width` components becomes row n; the last row stays.
void ShiftSteps(int width, int steps, std::vector<ScalarPrior>* priors) {
  for (int n = 0; n + 1 < steps; ++n) {
    for (int c = 0; c < width; ++c) (*priors)[n * width + c] = (*priors)[(n + 1) * width + c];
  }
}

void Replace(const std::vector<ComponentPriors>& components, int width, std::vector<ScalarPrior>* priors) {
  for (const ComponentPriors& c : components) {
    for (std::size_t n = 0; n < c.priors.size(); ++n) (*priors)[n * width + c.index] = c.priors[n];
  }
}

}  // namespace

absl::Status CheckStepState(int num_states, const Eigen::VectorXd& state) {
  if (state.size() != num_states) {
    return absl::FailedPreconditionError(
        absl::StrCat("state: expected ", num_states, " values (num_states), got ", state.size()));
  }
  for (int i = 0; i < num_states; ++i) {
    if (!std::isfinite(state(i))) {
      return absl::InvalidArgumentError(absl::StrCat("state[", i, "] = ", state(i), ": must be finite"));
    }
  }
  return absl::OkStatus();
}

absl::Status CheckPriorChanges(int L, int K, int N, const StepUpdate& update) {
  NUPMPC_RETURN_IF_ERROR(CheckComponents(update.inputs, "update.inputs", "num_inputs", L, N));
  return CheckComponents(update.outputs, "update.outputs", "num_outputs", K, N + 1);
}

void WritePriorChanges(const StepUpdate& update, int L, int K, int N, std::vector<ScalarPrior>* input_priors,
                       std::vector<ScalarPrior>* output_priors) {
  if (update.shift) {
    ShiftSteps(L, N, input_priors);
    ShiftSteps(K, N + 1, output_priors);
  }
  Replace(update.inputs, L, input_priors);
  Replace(update.outputs, K, output_priors);
}

absl::Status RefusePreviousInput(const StepUpdate& update) {
  if (!update.previous_input.has_value()) return absl::OkStatus();
  return absl::InvalidArgumentError("previous_input: only for sessions with input_differences");
}

absl::Status RefuseReference(const StepUpdate& update) {
  if (!update.reference.has_value()) return absl::OkStatus();
  return absl::InvalidArgumentError("reference: only for GP sessions; other sessions take new references in update");
}

absl::Status RefuseModel(const StepUpdate& update, const char* session_kind) {
  if (!update.changes_model()) return absl::OkStatus();
  return absl::FailedPreconditionError(
      absl::StrCat("model: ", session_kind, " take no model update (plain linear and keep-out sessions do)"));
}

}  // namespace nupmpc::core
