#ifndef NUPMPC_CORE_SESSION_STEP_UPDATE_H_
#define NUPMPC_CORE_SESSION_STEP_UPDATE_H_

// What one control period changes in a session before it solves: the measured state, the
// priors (references, bounds, weights), and for the session kinds that have them the input
// applied since the last period (input differences) and the output reference (GP). Every
// session kind takes the same StepUpdate through MpcSession::Apply, checks all of it, and
// only then changes anything: a rejected update leaves the session as it was.
//
// The field names mirror the API's Step (proto/nupmpc/v1/nupmpc.proto), and the messages
// of a rejected update name them ("update.inputs[0].index = 7: ..."), so the service only
// prefixes "step.".

#include <cstdint>
#include <optional>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "core/priors/scalar_prior.h"
#include "core/problem.h"
#include "core/session/model_update.h"

namespace nupmpc::core {

// All of one component's priors, replacing the session's for that component.
struct ComponentPriors {
  std::int64_t index = 0;           ///< input l or output k (wide enough for any index the API can send)
  std::vector<ScalarPrior> priors;  ///< one per step: N for an input, N + 1 for an output
};

struct StepUpdate {
  std::optional<Eigen::VectorXd> state;  ///< the measured x[0]; none keeps the previous one
  // update.shift: every per-step prior moves one step earlier (the last step repeated)
  // before the replacements below apply: receding-horizon references.
  bool shift = false;
  std::vector<ComponentPriors> inputs;   ///< update.inputs
  std::vector<ComponentPriors> outputs;  ///< update.outputs
  // Sessions with input differences only: u[-1], the input applied since the last step.
  // None: the first input of the session's last plan.
  std::optional<Eigen::VectorXd> previous_input;
  // GP sessions only: the output reference r[t..t+H-1] (H values, or 1 for all steps).
  std::optional<Eigen::VectorXd> reference;
  // Plain linear sessions (and keep-out ones, within the storage they have): new model
  // terms (core/session/model_update.h).
  ModelChanges model;

  bool changes_priors() const { return shift || !inputs.empty() || !outputs.empty(); }
  bool changes_model() const { return !model.empty(); }
};

// FAILED_PRECONDITION for a state of the wrong size, INVALID_ARGUMENT for a non-finite
// value ("state[2] = nan: must be finite").
absl::Status CheckStepState(int num_states, const Eigen::VectorXd& state);

// Checks the prior changes of `update` against a session with L inputs, K outputs and
// horizon N: indices in range, one prior per step, each prior valid. Does not check how
// the new priors combine (CheckPriorGrouping on the result does).
absl::Status CheckPriorChanges(int L, int K, int N, const StepUpdate& update);

// Writes the prior changes (checked by CheckPriorChanges) into the prior arrays of a
// problem with L inputs, K outputs and horizon N: the shift first, then the replacements.
void WritePriorChanges(const StepUpdate& update, int L, int K, int N, std::vector<ScalarPrior>* input_priors,
                       std::vector<ScalarPrior>* output_priors);

// INVALID_ARGUMENT naming the field when `update` sets previous_input (only sessions with
// input differences take it) or reference (only GP sessions take it).
absl::Status RefusePreviousInput(const StepUpdate& update);
absl::Status RefuseReference(const StepUpdate& update);
// FAILED_PRECONDITION naming `session_kind` (e.g. "GP sessions") when `update` changes the
// model.
absl::Status RefuseModel(const StepUpdate& update, const char* session_kind);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_STEP_UPDATE_H_
