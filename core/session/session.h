#ifndef NUPMPC_CORE_SESSION_SESSION_H_
#define NUPMPC_CORE_SESSION_SESSION_H_

#include <chrono>
#include <memory>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/algorithms/objective.h"
#include "core/algorithms/outer_iteration.h"
#include "core/options.h"
#include "core/problem.h"
#include "core/session/elastic.h"
#include "core/session/mpc_session.h"
#include "core/solution.h"

namespace nupmpc::core {

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

  const Problem& problem() const override { return problem_; }
  const SolverOptions& options() const { return options_; }
  Algorithm algorithm() const override { return algorithm_->algorithm(); }

  absl::Status SetInitialState(const Eigen::VectorXd& x0) override;
  // The state and prior changes of a control period, in place (no copy of the model);
  // previous_input and reference are refused (InputMappedSession, GpMpcSession take them).
  absl::Status Apply(const StepUpdate& update) override;
  // Replaces the problem's values, matrices included. The shape (dimensions, horizon,
  // which matrices vary per step, terminal cost present) must match: FAILED_PRECONDITION
  // otherwise.
  absl::Status Update(const Problem& problem);

  void ShiftWarmStart() override;
  void ResetWarmStart();
  // For idle sessions: frees the algorithm's scratch memory (most of the session's), keeps
  // the problem and the warm start. The next Solve() allocates it again before iterating.
  void ReleaseWorkspace() override { algorithm_->ReleaseWorkspace(); }
  bool has_warm_start() const { return has_warm_state_; }

  absl::StatusOr<SolveSummary> Solve(const SolveLimits& limits, Solution* solution) override;
  absl::StatusOr<SolveSummary> Solve(Solution* solution) { return Solve(SolveLimits{}, solution); }

 private:
  Session(Problem problem, SolverOptions options);
  absl::Status Rebuild();
  // After problem_'s values changed (Update, Apply): picks the algorithm for the new
  // priors, refreshes the current one or builds another (other priors may need another
  // algorithm, or IFFBDD another graph), and prepares the evaluator. On error nothing but
  // problem_ has changed; the caller puts its previous values back.
  absl::Status AdoptNewValues(bool was_input_constrained);
  // has_binary_inputs_, has_nonconvex_priors_, hard_bounds_, elastic_applies_ from problem_.
  void DerivePriorFlags();
  // The solve's pass budget: the limits' cap within the options' one.
  int IterationCap(const SolveLimits& limits) const;
  SolveSummary RunLoop(const SolveLimits& limits, bool warm);
  // The elastic fallback (SolverOptions.elastic_slope) for the rest of the solve's budget
  // after the hard problem's loop stopped unconverged: solves the elastic form, restores
  // the hard bounds and reports the plan against them.
  void ContinueElastic(const SolveLimits& limits, int max_iterations, SolveSummary* summary);
  // Between passes: whether the solve's interrupt fires now (reads the clock and the flag);
  // if so its reason becomes the summary's status.
  bool StopNow(SolveSummary* summary);
  // After an algorithm call: whether the interrupt fired inside it (the pass is
  // incomplete: its iterate is discarded, the carried state is reset after the solve).
  bool PassInterrupted(SolveSummary* summary);
  // Makes the binary inputs of the returned plan discrete (SolverOptions.discrete_fixing_*:
  // at once, or block by block with re-solves in between) and re-evaluates it.
  void MakeInputsDiscrete(SolveSummary* summary);
  // Rounds the binaries of step n of best_ to their nearer levels (an M-level run as its
  // sum), pins them in the algorithm if `pin`, and returns the largest distance moved.
  double RoundDiscreteStep(int n, bool pin);
  // The discrete local search (SolverOptions.discrete_search_sweeps) on the rounded best_;
  // counts its moves in the summary (and a limit that stops it in its status) and returns
  // the evaluation of the plan it ends with.
  ObjectiveEvaluator::Result SearchDiscreteNeighbours(SolveSummary* summary);
  // When the single moves are exhausted: moves two levels of the same binary group at
  // once, each to a neighbouring step, for every pair of steps that carry a level at most
  // SolverOptions.discrete_pair_reach apart (first improvement). On an integrator, one
  // level moved earlier and a later one moved later lifts only the stretch between them:
  // the correction a single move cannot make without shifting everything after it.
  // `try_move` is the search's evaluate-and-keep-or-undo step.
  template <typename TryMove>
  bool TryPairMove(SolveSummary* summary, TryMove& try_move);
  // Moves one level of the group at inputs first..last from step n to step n + direction
  // (±1) if both steps carry that group, n has a level and the other step room for it.
  bool MoveOneLevel(int n, int direction, int first, int last);
  // Binary group (one binary, or an M-level run) starting at input l of step n: how many
  // of its binaries are high, and setting that count.
  int GroupLevel(int n, int first, int last) const;
  void SetGroupLevel(int n, int first, int last, int level);
  // The last input of the binary group that starts at input `first` of step n (an M-level
  // run of binaries marked rounds_with_next, or the binary itself).
  int GroupEnd(int n, int first) const;
  // Whether step `other` has the same binary group as step n at inputs first..last.
  bool SameGroupAt(int n, int other, int first, int last) const;

  Problem problem_;
  // Apply()'s scratch: the candidate priors are written here and swapped into problem_;
  // after a swap they hold the previous ones (to put back if the new ones are refused).
  std::vector<ScalarPrior> scratch_input_priors_, scratch_output_priors_;
  Eigen::VectorXd scratch_state_;  ///< likewise for x[0] when an update changes both
  SolverOptions options_;
  std::unique_ptr<OuterIteration> algorithm_;
  ObjectiveEvaluator evaluator_;
  PrimalIterate current_, candidate_, best_;
  bool has_warm_state_ = false;
  bool has_binary_inputs_ = false;  ///< derived from problem_ whenever it is replaced
  bool has_nonconvex_priors_ = false;  ///< likewise
  HardBounds hard_bounds_;             ///< likewise: the hard output bounds
  bool elastic_applies_ = false;       ///< likewise: the elastic fallback is on and applies
  double flops_per_step_ = 0.0;        ///< EstimateFootprint: sets the interrupt's poll interval
  // During Solve(): its interrupt (time limit, cancel flag), polled inside the passes too,
  // and whether it fired inside an algorithm call.
  Interrupt* interrupt_ = nullptr;
  bool pass_interrupted_ = false;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_SESSION_H_
