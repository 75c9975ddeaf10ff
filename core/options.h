#ifndef NUPMPC_CORE_OPTIONS_H_
#define NUPMPC_CORE_OPTIONS_H_

#include <atomic>
#include <cmath>
#include <functional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace nupmpc::core {

// Which outer iteration runs (nup-algorithms.md §4).
enum class Algorithm {
  kAuto,    ///< choose from the priors present (§4 selection rule)
  kIake,    ///< IAKE / IRLGE: smoother + NUP updates; general, hard constraints need finite slope
  kIbffd,   ///< backward information filter, forward deciding: convex priors on inputs only
  kIffbdd,  ///< forward Kalman filter, backward dual deciding: convex priors on outputs (+ inputs)
};
const char* AlgorithmName(Algorithm algorithm);
absl::StatusOr<Algorithm> ParseAlgorithm(const std::string& name);

// Setup-time options: fixed when a Session is created. Per-solve limits are in SolveLimits.
struct SolverOptions {
  Algorithm algorithm = Algorithm::kAuto;

  // Relative change of the objective between iterations, |J_i - J_{i-1}| ≤ tol·|J_i|
  // (nup-algorithms.md §11). Together with the violation test below.
  double objective_tolerance = 1e-10;

  // Max constraint violation accepted at convergence, relative to the problem's bound
  // scale (largest finite bound magnitude, at least 1e-3). Also the accuracy the
  // active-set polish must reach to be accepted.
  double violation_tolerance = 1e-9;

  // Active-set polish: once the set of active constraints has not changed for this
  // many iterations, solve the equality-constrained problem exactly with one extra
  // message-passing pass and accept it if it satisfies the optimality conditions.
  // 0 disables polishing (the plain algorithms of the papers).
  int polish_after_stable_iterations = 1;
  // An iteration counts as "not changed" when at most this fraction of the decided scalars
  // changed region. On large problems the last few scalars settle slowly while the
  // correction steps of the polish fix them at once; 0 waits for a set that does not
  // change at all.
  double polish_settled_fraction = 1e-3;
  // The same when the polish would run on an input sub-problem (IFFBDD with constrained
  // inputs and every output constraint inactive): that polish is IBFFD's active-set method
  // on the inputs alone, whose corrections recover from a rough active set, while IFFBDD's
  // own iterate settles the last input regions slowly.
  double input_polish_settled_fraction = 0.1;
  // Primal-dual active-set corrections tried after a failed polish before the plain
  // iteration resumes, and up to polish_max_rounds while the deciding residual keeps
  // falling (stiff problems such as ibffd_2d need more, and the plain iteration does not
  // know what the corrections found).
  int polish_rounds = 4;
  int polish_max_rounds = 12;
  // IFFBDD problems whose only constraints are hard output bounds are iterated with a
  // primal-dual interior-point method on the same Kalman passes until the polish finds
  // the active set (core/algorithms/interior_point_rows.h); false keeps IFFBDD's own dual
  // NUP updates. Needs the polish (polish_after_stable_iterations > 0).
  bool interior_point = true;

  // IAKE: slope used for hard constraints (IRLGE needs a finite penalty; it must exceed
  // the constraint's Lagrange multiplier to be exact, §6.2).
  double iake_hard_slope = 1e4;
  // IAKE: NUP variances of constraint priors are floored at this times (bound scale)²
  // to avoid zero-variance sticking (§6.3).
  double iake_variance_floor = 0.0;

  // IBFFD: initial slopes of hard half-spaces / boxes before adaptation (§8.3).
  double ibffd_initial_halfspace_slope = 5.0;
  double ibffd_initial_box_slope = 10.0;

  // Binary and M-level inputs: after the iteration loop, the plan is made discrete. With
  // discrete_fixing_passes = 0 every binary is rounded at once (§7.2). Otherwise the
  // horizon is cut into discrete_fixing_blocks blocks; from the first block on, the block's
  // binaries are rounded and pinned and discrete_fixing_passes IAKE passes let the later
  // inputs make up for the rounding ("fix and re-solve"). Rounding a long plan of an
  // integrator at once lets small errors of the early inputs grow along the horizon (the
  // flappy bird misses its slits, the three-level corridor leaves the corridor). These
  // passes come on top of max_iterations and stop at the solve's time limit or cancel
  // flag, which then rounds the rest at once.
  int discrete_fixing_passes = 10;
  int discrete_fixing_blocks = 30;
  // Then a local search on the discrete plan: one input one level up or down, or one level
  // moved between two neighbouring steps (a flap or a switch one step earlier or later, or
  // a +1/-1 doublet), kept when it lowers the max violation or, at no worse violation, J.
  // Each try is one O(N) evaluation of the plan; a sweep tries every move once. Up to this
  // many sweeps, until one finds nothing (0: off).
  int discrete_search_sweeps = 20;
  // When a sweep finds no single move: two levels moved at once, each to a neighbouring
  // step, at steps at most this far apart (0: off). One flap earlier and a later one later
  // lifts only the stretch between them. Each pair tries four moves, so a pair sweep costs
  // up to 4 · (steps with a level) · reach evaluations. The reach must span the distance
  // between a correction's two moves (on the flappy bird, from a flap to the next slit).
  int discrete_pair_reach = 150;

  // Elastic fallback (core/session/elastic.h) for output bounds that cannot all be met.
  // With elastic_slope > 0, an IFFBDD solve with hard output bounds that has not converged
  // after elastic_after_iterations passes continues, for the rest of its budget, on the
  // problem with every hard output bound replaced by the exact penalty
  // elastic_slope·distance (input bounds stay hard: the actuator's limits). If that plan
  // meets every bound it is the hard problem's optimum (status converged); otherwise the
  // solve reports SolveStatus::kInfeasible with the plan minimising
  // J + slope·(distance outside the output bounds). On a feasible problem the first case
  // needs a slope above the bounds' Lagrange multipliers (J's units per unit of the
  // bounded output). 0: off, the solve runs to its iteration limit.
  double elastic_slope = 0.0;
  int elastic_after_iterations = 200;

  // Default per-solve iteration cap (SolveLimits may lower it).
  int max_iterations = 5000;
};

absl::Status Validate(const SolverOptions& options);

// One pass of a solve, as SolveLimits.trace reports it.
struct PassTrace {
  enum class Kind { kIterate, kPolish };
  Kind kind = Kind::kIterate;
  int pass = 0;                ///< passes of this solve so far, this one included
  int changed = -1;            ///< kIterate: scalars whose region changed (-1: not tracked)
  double objective = NAN;      ///< kIterate: the iterate's objective
  double max_violation = NAN;  ///< kIterate: and its largest constraint violation
  double residual = NAN;       ///< kPolish: the deciding residual (0: the candidate is optimal)
};

// Per-solve limits and control.
struct SolveLimits {
  int max_iterations = 0;  ///< 0: use SolverOptions.max_iterations
  // Both are polled between passes and inside them, every few time steps (a Session
  // returns within about one time step of a pass: core/algorithms/interrupt.h).
  double time_limit_seconds = 0.0;            ///< 0: none; wall time for the whole solve (Solve() to return)
  const std::atomic<bool>* cancel = nullptr;  ///< may be null; a cancelled solve returns no plan
  bool warm_start = true;                     ///< start from the session's carried state if any
  // Called after every pass whose result was evaluated (null: none): how the active set
  // and the objective converge, for studies of the pass counts (nupmpc-bench --trace).
  // Not for the service.
  std::function<void(const PassTrace&)> trace;
};

absl::Status Validate(const SolveLimits& limits);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_OPTIONS_H_
