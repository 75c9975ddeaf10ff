#ifndef NUPMPC_CORE_SESSION_SOLVE_LOOP_H_
#define NUPMPC_CORE_SESSION_SOLVE_LOOP_H_

#include "core/algorithms/interrupt.h"
#include "core/algorithms/objective.h"
#include "core/algorithms/primal_iterate.h"
#include "core/options.h"
#include "core/problem.h"
#include "core/session/infeasibility.h"
#include "core/solution.h"

namespace nupmpc::core {

class OuterIteration;  // core/algorithms/outer_iteration.h

// After an algorithm call: whether `interrupt` fired inside it. If so the pass is
// incomplete (its iterate is discarded, the carried state is reset after the solve):
// the summary gets the interrupt's reason and *pass_interrupted is set.
bool PassInterrupted(const Interrupt& interrupt, SolveSummary* summary, bool* pass_interrupted);

// What one iteration loop works on: the session's algorithm, evaluator and iterates, all
// sized when the session was built (the loop allocates nothing).
struct SolveLoopParts {
  const Problem& problem;
  const SolverOptions& options;
  OuterIteration& algorithm;
  ObjectiveEvaluator& evaluator;
  Interrupt& interrupt;
  PrimalIterate& current;          ///< a plain pass's iterate
  PrimalIterate& candidate;        ///< a polish pass's iterate
  PrimalIterate& best;             ///< the plan; on entry the carried one (the settling test compares with it)
  PrimalIterate& least_violation;  ///< the plain iterate closest to the bounds
  InfeasibilityWatch& infeasibility;
  bool& pass_interrupted;  ///< set when the interrupt fires inside an algorithm call
  bool nonconvex_priors;   ///< some prior is non-convex: the plan must settle, not J alone
};

// One solve's iteration loop with the active-set polish (Session::Solve runs it, and the
// elastic fallback again on its elastic problem): plain passes until the plan and J settle
// within the bounds, the passes show the bounds contradictory, a limit is reached, or a
// polish started once the active set has settled verifies a plan. A warm solve first
// tries the carried active set. Leaves its plan in `best`.
class SolveLoop {
 public:
  SolveLoop(const SolveLoopParts& parts, const SolveLimits& limits, int max_iterations);

  SolveSummary Run(bool warm);

 private:
  // What a polish pass's plan became.
  enum class Verdict { kAccepted, kRejected, kCutShort };

  // Whether the limits stop the loop before its next pass (the status then says which).
  bool StopRequested();
  // Whether the interrupt fired inside the last algorithm call (PassInterrupted above).
  bool PassInterrupted();
  // After an evaluation: a pass the interrupt cut short there is neither returned nor
  // counted (the plan returned is the previous pass's, as a solve capped there returns it).
  bool EvaluationCutShort();

  // One plain pass and what it shows; false when the loop ends with it.
  bool Pass();
  // Whether the plain pass in `current` moved the inputs no more than a settled plan does
  // (always, without non-convex priors: J then settles only with the plan).
  bool IterateSettled() const;
  // Keeps the plan in `best` as the least violating so far if it is (objective and
  // violation `r`).
  void KeepIfLeastViolation(const ObjectiveEvaluator::Result& r);
  // Whether `changed` region changes count as a settled active set.
  bool Settled(int changed) const;
  // Counts the passes the active set stayed settled and polishes once it has for long
  // enough; true when the loop ends (a polish was accepted or interrupted).
  bool PolishWhenSettled(int changed);

  // Tries the active-set polish (1 + polish_rounds passes, more up to polish_max_rounds
  // while the deciding residual keeps falling); true if it was accepted.
  bool TryPolish();
  // A polish pass whose deciding residual is `residual`: its plan is returned as verified
  // if it is within the bounds.
  Verdict AcceptIfVerified(double residual);
  // Until a plain iterate exists, a complete polish pass's finite plan is the solve's.
  Verdict KeepIfFirstFinite();

  const SolveLoopParts p_;
  const SolveLimits& limits_;
  const int max_iterations_;
  const double violation_tolerance_;
  const bool polish_enabled_;

  SolveSummary summary_;
  bool have_finite_ = false;  ///< best holds a complete, finite iterate of this loop
  // The plain iterate of this loop closest to the bounds, returned if the loop finds them
  // contradictory (the last iterate has then diverged with the multipliers).
  double least_violation_;
  double least_violation_objective_ = 0.0;
  double previous_objective_;
  int stable_ = 0;   ///< passes in a row whose active set counted as settled
  int polish_wait_;  ///< settled passes before the next polish attempt
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_SOLVE_LOOP_H_
