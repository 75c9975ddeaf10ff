#ifndef NUPMPC_CORE_SESSION_INPUT_MAPPED_SESSION_H_
#define NUPMPC_CORE_SESSION_INPUT_MAPPED_SESSION_H_

// Multi-level inputs (core/model/multilevel_inputs.h) and priors on input differences
// (core/model/input_differences.h) around any session: the inner session solves the
// expanded or augmented problem, the caller states, updates and reads its own inputs,
// outputs and states. The session owns u[-1], the input applied before the horizon, which
// an input-difference problem carries in its state: the step's previous_input when given
// (for that step only), else the first input of the last plan (or the spec's at creation).

#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/model/multilevel_inputs.h"
#include "core/session/mpc_session.h"
#include "core/snapshot/state_archive.h"

namespace nupmpc::core {

// How the caller's inputs map to the inner problem's.
struct InputMap {
  std::vector<InputLevels> levels;  ///< one per input (count 0: ordinary), or empty: none
  bool differences = false;
  std::vector<ScalarPrior> difference_priors;  ///< N·L priors on Δu[n] (differences only)
  Eigen::VectorXd previous_input;              ///< u[-1] at creation (differences only)

  bool active() const { return differences || !levels.empty(); }
};

// The problem the inner session solves for `base` (`base` itself without an active map).
// INVALID_ARGUMENT naming the field ("input_levels: ...", "delta_priors: ...") when the
// map does not fit the problem.
absl::StatusOr<Problem> MapInputs(Problem base, const InputMap& map);

class InputMappedSession final : public MpcSession {
 public:
  // `inner` solves MapInputs(base, map) (a Session, a KeepOutSession, ...); `caller` is
  // DimensionsOf(base). Without an active map, `inner` is returned as it is.
  static std::unique_ptr<MpcSession> Wrap(std::unique_ptr<MpcSession> inner, InputMap map, Dimensions caller);

  const Problem& problem() const override { return inner_->problem(); }
  Algorithm algorithm() const override { return inner_->algorithm(); }
  Dimensions dimensions() const override { return dimensions_; }

  // The caller's x[0] (M values).
  absl::Status SetInitialState(const Eigen::VectorXd& x0) override;
  // The inputs' priors are fixed at creation (update.inputs: FAILED_PRECONDITION); output
  // updates name the caller's outputs; previous_input only with input differences.
  absl::Status Apply(const StepUpdate& update) override;
  void ShiftWarmStart() override { inner_->ShiftWarmStart(); }
  void ReleaseWorkspace() override { inner_->ReleaseWorkspace(); }
  // The inner plan in the caller's terms; with input differences, its u[0] becomes the
  // next solve's u[-1].
  absl::StatusOr<SolveSummary> Solve(const SolveLimits& limits, Solution* solution) override;

  // u[-1] (the next step's default and the one the inner problem holds now) and the inner
  // session's own snapshot.
  absl::Status SaveState(std::string* out) override;
  absl::Status RestoreState(std::string_view bytes) override;

 private:
  InputMappedSession(std::unique_ptr<MpcSession> inner, InputMap map, Dimensions dimensions);
  // The inner x[0]: [x[0]; u[-1]] with input differences, else x[0].
  void WriteInnerState(const Eigen::VectorXd& x0, const Eigen::VectorXd& previous_input);
  absl::Status CheckPreviousInput(const StepUpdate& update) const;
  // Snapshots: both directions; `inner` holds the inner session's bytes.
  void PersistState(StateArchive& archive, std::string& inner);
  // Input differences: entries that undo a shift's move of u[0]'s prior onto u[-1].
  void KeepFixedInputFree(StepUpdate* inner) const;

  std::unique_ptr<MpcSession> inner_;
  InputMap map_;                            ///< its previous_input: the next step's default u[-1]
  Dimensions dimensions_;                   ///< the caller's
  Eigen::VectorXd inner_state_;             ///< scratch for the inner x[0]
  Eigen::VectorXd applied_previous_input_;  ///< the u[-1] of the inner problem now
  Solution own_plan_;                       ///< Solve()'s plan when the caller passes none
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_INPUT_MAPPED_SESSION_H_
