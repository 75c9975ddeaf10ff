#include "core/session/input_mapped_session.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/model/input_differences.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {

absl::StatusOr<Problem> MapInputs(Problem base, const InputMap& map) {
  if (map.differences && !map.levels.empty()) {
    return absl::InvalidArgumentError("input_differences: cannot be combined with input_levels yet");
  }
  if (map.differences) return AugmentWithInputDifferences(base, map.difference_priors, map.previous_input);
  if (map.levels.empty()) return base;
  absl::StatusOr<Problem> expanded = ExpandMultiLevelInputs(base, map.levels);
  if (!expanded.ok()) return absl::InvalidArgumentError(absl::StrCat("input_levels: ", expanded.status().message()));
  return expanded;
}

std::unique_ptr<MpcSession> InputMappedSession::Wrap(std::unique_ptr<MpcSession> inner, InputMap map,
                                                     Dimensions caller) {
  if (!map.active()) return inner;
  return std::unique_ptr<MpcSession>(new InputMappedSession(std::move(inner), std::move(map), caller));
}

InputMappedSession::InputMappedSession(std::unique_ptr<MpcSession> inner, InputMap map, Dimensions dimensions)
    : inner_(std::move(inner)), map_(std::move(map)), dimensions_(dimensions) {
  inner_state_ = inner_->problem().initial_mean;
  applied_previous_input_ = map_.previous_input;
}

void InputMappedSession::WriteInnerState(const Eigen::VectorXd& x0, const Eigen::VectorXd& previous_input) {
  inner_state_.head(dimensions_.num_states) = x0;
  inner_state_.tail(dimensions_.num_inputs) = previous_input;
}

absl::Status InputMappedSession::SetInitialState(const Eigen::VectorXd& x0) {
  NUPMPC_RETURN_IF_ERROR(CheckStepState(dimensions_.num_states, x0));
  if (!map_.differences) return inner_->SetInitialState(x0);
  WriteInnerState(x0, map_.previous_input);
  NUPMPC_RETURN_IF_ERROR(inner_->SetInitialState(inner_state_));
  applied_previous_input_ = map_.previous_input;
  return absl::OkStatus();
}

absl::Status InputMappedSession::CheckPreviousInput(const StepUpdate& update) const {
  if (!map_.differences) return RefusePreviousInput(update);
  if (!update.previous_input.has_value()) return absl::OkStatus();
  const Eigen::VectorXd& u = *update.previous_input;
  const int L = dimensions_.num_inputs;
  if (u.size() != L) {
    return absl::FailedPreconditionError(
        absl::StrCat("previous_input: expected ", L, " values (num_inputs), got ", u.size()));
  }
  for (int l = 0; l < L; ++l) {
    if (!std::isfinite(u(l)))
      return absl::InvalidArgumentError(absl::StrCat("previous_input[", l, "]: must be finite"));
  }
  return absl::OkStatus();
}

absl::Status InputMappedSession::Apply(const StepUpdate& update) {
  NUPMPC_RETURN_IF_ERROR(RefuseReference(update));
  NUPMPC_RETURN_IF_ERROR(RefuseModel(update, "sessions with input_levels or input_differences"));
  if (!update.inputs.empty()) {
    return absl::FailedPreconditionError(
        "update.inputs: this session's inputs are multi-level or carry input-difference priors; their priors are "
        "fixed at creation");
  }
  NUPMPC_RETURN_IF_ERROR(CheckPreviousInput(update));
  if (update.state.has_value()) NUPMPC_RETURN_IF_ERROR(CheckStepState(dimensions_.num_states, *update.state));
  // The caller's outputs are the inner problem's first K.
  NUPMPC_RETURN_IF_ERROR(
      CheckPriorChanges(dimensions_.num_inputs, dimensions_.num_outputs, dimensions_.horizon, update));
  if (!map_.differences) return inner_->Apply(update);

  // u[-1] is part of the inner x[0], which therefore changes every step.
  const Eigen::VectorXd& previous_input = update.previous_input.value_or(map_.previous_input);
  WriteInnerState(update.state.has_value()
                      ? *update.state
                      : Eigen::VectorXd(inner_->problem().initial_mean.head(dimensions_.num_states)),
                  previous_input);
  StepUpdate inner;
  inner.state = inner_state_;
  if (update.changes_priors()) {
    inner.shift = update.shift;
    inner.outputs = update.outputs;
    if (update.shift) KeepFixedInputFree(&inner);
  }
  NUPMPC_RETURN_IF_ERROR(inner_->Apply(inner));
  applied_previous_input_ = previous_input;
  return absl::OkStatus();
}

void InputMappedSession::KeepFixedInputFree(StepUpdate* inner) const {
  // The inner outputs K..K+L-1 carry u[n-1] at step n: the priors on u[0..N-1] sit at
  // steps 1..N, and step 0 holds the fixed u[-1]. A plain shift would move u[0]'s prior
  // onto u[-1]; these entries (applied after the shift) shift steps 1..N only.
  const Problem& now = inner_->problem();
  const int K = dimensions_.num_outputs, N = dimensions_.horizon;
  for (int l = 0; l < dimensions_.num_inputs; ++l) {
    ComponentPriors carried{.index = K + l, .priors = std::vector<ScalarPrior>(N + 1)};
    carried.priors[0] = now.output_prior(0, K + l);
    for (int n = 1; n <= N; ++n) carried.priors[n] = now.output_prior(std::min(n + 1, N), K + l);
    inner->outputs.push_back(std::move(carried));
  }
}

absl::StatusOr<SolveSummary> InputMappedSession::Solve(const SolveLimits& limits, Solution* solution) {
  Solution* plan = solution != nullptr ? solution : &own_plan_;
  NUPMPC_ASSIGN_OR_RETURN(const SolveSummary summary, inner_->Solve(limits, plan));
  if (!summary.has_plan) return summary;
  // Rows are steps: the inner inputs are N × L' (binaries or differences).
  if (map_.differences) {
    plan->inputs = InputsFromDifferences(plan->inputs, applied_previous_input_);
    if (plan->inputs.rows() > 0) map_.previous_input = plan->inputs.row(0).transpose();
  } else {
    plan->inputs = InputsFromLevels(plan->inputs, map_.levels);
  }
  plan->outputs = plan->outputs.leftCols(dimensions_.num_outputs).eval();
  plan->states = plan->states.leftCols(dimensions_.num_states).eval();
  return summary;
}

absl::Status InputMappedSession::SaveState(std::string* out) {
  std::string inner;
  NUPMPC_RETURN_IF_ERROR(inner_->SaveState(&inner));
  StateWriter writer(out);
  PersistState(writer, inner);
  return writer.status();
}

absl::Status InputMappedSession::RestoreState(std::string_view bytes) {
  std::string inner;
  StateReader reader(bytes);
  PersistState(reader, inner);
  NUPMPC_RETURN_IF_ERROR(reader.status());
  const absl::Status restored = inner_->RestoreState(inner);
  if (restored.ok() || restored.code() != absl::StatusCode::kInvalidArgument) return restored;
  return absl::InvalidArgumentError(absl::StrCat("input_mapped.inner: ", restored.message()));
}

void InputMappedSession::PersistState(StateArchive& archive, std::string& inner) {
  archive.BeginSection("input_mapped");
  bool differences = map_.differences;
  archive.Flag("differences", differences);
  if (archive.restoring() && archive.ok() && differences != map_.differences) {
    return archive.Fail("differences", "this session maps its inputs otherwise");
  }
  if (map_.differences) {
    archive.Field("previous_input", map_.previous_input);
    archive.Field("applied_previous_input", applied_previous_input_);
  }
  // Bounded by the input itself (the reader checks what is left before copying).
  archive.Blob("inner", inner, std::numeric_limits<std::size_t>::max());
  archive.EndSection();
}

}  // namespace nupmpc::core
