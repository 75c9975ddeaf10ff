#ifndef NUPMPC_CORE_SESSION_ELASTIC_H_
#define NUPMPC_CORE_SESSION_ELASTIC_H_

// The elastic fallback of a session (SolverOptions.elastic_slope): a problem whose hard
// output bounds cannot all be met (a measured state outside what the inputs can correct,
// contradictory bounds) has no solution, and a dual method such as IFFBDD then runs to its
// iteration limit. Its elastic form replaces every hard output box and half-space by the
// exact penalty slope·(distance outside the bound), which always has a minimiser; one that
// meets every bound solves the hard problem too (it minimises J over a larger set), and
// one that does not is the least-penalty plan a controller can still apply. Input bounds
// stay hard: they are the actuator's limits, and the plan must be one it can apply.

#include <vector>

#include "core/algorithms/interrupt.h"
#include "core/algorithms/objective.h"
#include "core/options.h"
#include "core/priors/scalar_prior.h"
#include "core/problem.h"
#include "core/solution.h"

namespace nupmpc::core {

// The hard output bounds of a problem: indices into Problem::output_priors.
using HardBounds = std::vector<int>;

// Fills `bounds` (reusing its storage: no allocation once it has grown to size).
void FindHardOutputBounds(const Problem& problem, HardBounds* bounds);

// Gives every bound in `bounds` the slope `slope` (+∞ makes them hard again).
void SetBoundSlopes(const HardBounds& bounds, double slope, Problem* problem);

// Whether the session's algorithm also solves the elastic form: IFFBDD, the algorithm of
// output constraints, whose conditions (prior kinds, Gaussian parts on the inputs) the
// elastic form keeps. IAKE turns hard bounds into finite slopes itself; IBFFD has no
// output bounds.
inline bool ElasticFormApplies(const HardBounds& bounds, Algorithm algorithm) {
  return !bounds.empty() && algorithm == Algorithm::kIffbdd;
}

// The continuation of a solve on the elastic form: for the rest of the solve's pass budget
// after the hard problem's loop stopped at its own budget unconverged. Holds what it
// derives from the session's problem; the session's loop is reached through Solve.
class ElasticFallback {
 public:
  // The session's side: its problem, algorithm, evaluator and iteration loop.
  class Solve {
   public:
    virtual ~Solve() = default;
    virtual Problem* mutable_problem() = 0;
    // The output priors' slopes changed: the algorithm and the evaluator take them over.
    virtual void OutputPriorsChanged() = 0;
    // The algorithm forgets its carried state.
    virtual void ColdStart() = 0;
    // The session's iteration loop (polish included) on the current problem; leaves its
    // plan as the session's best iterate.
    virtual SolveSummary RunLoop(const SolveLimits& limits, bool warm) = 0;
    // The best iterate against the current problem, not interrupted.
    virtual ObjectiveEvaluator::Result EvaluatePlan() = 0;
  };

  // From the session's problem (whenever it is replaced), options and algorithm.
  void Derive(const Problem& problem, const SolverOptions& options, Algorithm algorithm) {
    FindHardOutputBounds(problem, &hard_bounds_);
    slope_ = options.elastic_slope;
    applies_ = slope_ > 0.0 && ElasticFormApplies(hard_bounds_, algorithm);
  }
  // Whether the fallback is on and the problem has bounds it can relax.
  bool applies() const { return applies_; }

  // Solves the elastic form with the budget max_iterations - summary->iterations (the
  // time limit and the cancel flag act through `interrupt`), restores the hard bounds and
  // reports the plan against them: `summary` becomes the whole solve's (kInfeasible when
  // the elastic plan converged outside the hard bounds by more than `violation_tolerance`).
  void Continue(Solve* solve, Interrupt* interrupt, const SolveLimits& limits, int max_iterations,
                double violation_tolerance, SolveSummary* summary) const;

 private:
  HardBounds hard_bounds_;
  double slope_ = 0.0;
  bool applies_ = false;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_ELASTIC_H_
