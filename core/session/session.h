#ifndef NUPMPC_CORE_SESSION_SESSION_H_
#define NUPMPC_CORE_SESSION_SESSION_H_

#include <chrono>
#include <memory>
#include <string>
#include <string_view>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/algorithms/interrupt.h"
#include "core/algorithms/objective.h"
#include "core/algorithms/primal_iterate.h"
#include "core/options.h"
#include "core/problem.h"
#include "core/session/elastic.h"
#include "core/session/infeasibility.h"
#include "core/session/mpc_session.h"
#include "core/solution.h"

namespace nupmpc::core {

class OuterIteration;  // core/algorithms/outer_iteration.h: the algorithm behind the session
class StateArchive;    // core/snapshot/state_archive.h

// A problem of fixed shape, the algorithm's workspace, and the warm-start state carried
// from one solve to the next (acados' memory/workspace split; OSQP's three update levels):
//
//  * Create(problem, options): validates, picks the algorithm, allocates everything.
//  * SetInitialState / Update: new x0, references, bounds, matrices of the same shape.
//    Validated before anything changes: a rejected update leaves the session as it was.
//  * Solve(limits): per-solve iteration cap, wall-time limit, cancel flag, warm or cold.
//    The limits are polled inside every pass every k time steps (k from the per-step flop
//    count, core/algorithms/interrupt.h): a stopped solve returns within about one time
//    step of a pass (and the O(N·M²) simulation of the plan it returns). An interrupted
//    pass is discarded and the carried warm start reset (the next solve starts cold).
//    The iteration loop allocates nothing.
//  * ShiftWarmStart(): receding horizon; the carried state moves one step earlier.
//
// Thread safety: none; one thread uses a session at a time.
class Session final : public MpcSession {
 public:
  static absl::StatusOr<std::unique_ptr<Session>> Create(Problem problem, SolverOptions options = {});
  ~Session() override;

  const Problem& problem() const override { return problem_; }
  const SolverOptions& options() const { return options_; }
  Algorithm algorithm() const override;

  absl::Status SetInitialState(const Eigen::VectorXd& x0) override;
  // The state, prior and model changes of a control period, in place (the model terms are
  // copied only when the update changes them); previous_input and reference are refused
  // (InputMappedSession, GpMpcSession take them). A change that makes A, B or C per-step
  // builds the algorithm again: the warm start restarts once.
  absl::Status Apply(const StepUpdate& update) override;
  // Replaces the problem's values, matrices included. The shape (dimensions, horizon,
  // which matrices vary per step, terminal cost present) must match: FAILED_PRECONDITION
  // otherwise.
  absl::Status Update(const Problem& problem);

  void ShiftWarmStart() override;
  void ResetWarmStart();
  // For idle sessions: frees the algorithm's scratch memory (most of the session's), keeps
  // the problem and the warm start. The next Solve() allocates it again before iterating.
  void ReleaseWorkspace() override;
  bool has_warm_start() const { return has_warm_state_; }

  absl::StatusOr<SolveSummary> Solve(const SolveLimits& limits, Solution* solution) override;
  absl::StatusOr<SolveSummary> Solve(Solution* solution) { return Solve(SolveLimits{}, solution); }

  // The problem's values, the carried iterate and the algorithm's carried state
  // (session_state.cc).
  absl::Status SaveState(std::string* out) override;
  absl::Status RestoreState(std::string_view bytes) override;

 private:
  // The session's side of the discrete search and the elastic fallback (session.cc).
  class Hooks;

  Session(Problem problem, SolverOptions options);
  absl::Status Rebuild();
  // After problem_'s values changed (Update, Apply): picks the algorithm for the new
  // priors, refreshes the current one or builds another (other priors may need another
  // algorithm, or IFFBDD another graph), and prepares the evaluator. On error nothing but
  // problem_ has changed; the caller puts its previous values back.
  absl::Status AdoptNewValues(bool was_input_constrained, bool new_storage = false);
  // has_binary_inputs_, has_nonconvex_priors_, elastic_, flops_per_step_ from problem_.
  void DerivePriorFlags();
  // The solve's pass budget: the limits' cap within the options' one.
  int IterationCap(const SolveLimits& limits) const;
  // The iteration loop with the active-set polish; leaves its plan in best_.
  SolveSummary RunLoop(const SolveLimits& limits, bool warm);
  // After an algorithm call: whether the interrupt fired inside it (the pass is
  // incomplete: its iterate is discarded, the carried state is reset after the solve).
  bool PassInterrupted(SolveSummary* summary);
  // Snapshots (session_state.cc): both directions in one function.
  void PersistState(StateArchive& archive);
  // A restore's problem values, adopted as an update's are (validated; the algorithm
  // refreshed, or rebuilt when the values need another one or the model's storage
  // changed). On error the session's values are unchanged.
  absl::Status AdoptRestoredValues(Problem values);

  Problem problem_;
  // Apply()'s scratch: the candidate priors are written here and swapped into problem_;
  // after a swap they hold the previous ones (to put back if the new ones are refused).
  std::vector<ScalarPrior> scratch_input_priors_, scratch_output_priors_;
  Eigen::VectorXd scratch_state_;  ///< likewise for x[0] when an update changes both
  ModelTerms scratch_model_;       ///< likewise for the model terms
  SolverOptions options_;
  std::unique_ptr<OuterIteration> algorithm_;
  ObjectiveEvaluator evaluator_;
  PrimalIterate current_, candidate_, best_;
  PrimalIterate least_violation_;     ///< RunLoop: its plain iterate closest to the bounds
  InfeasibilityWatch infeasibility_;  ///< RunLoop: whether its passes show no feasible point
  bool has_warm_state_ = false;
  bool has_binary_inputs_ = false;     ///< derived from problem_ whenever it is replaced
  bool has_nonconvex_priors_ = false;  ///< likewise
  ElasticFallback elastic_;            ///< likewise: the hard output bounds
  double flops_per_step_ = 0.0;        ///< EstimateFootprint: sets the interrupt's poll interval
  // During Solve(): its interrupt (time limit, cancel flag), polled inside the passes too,
  // and whether it fired inside an algorithm call.
  Interrupt* interrupt_ = nullptr;
  bool pass_interrupted_ = false;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_SESSION_H_
