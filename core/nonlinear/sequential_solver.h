#ifndef NUPMPC_CORE_NONLINEAR_SEQUENTIAL_SOLVER_H_
#define NUPMPC_CORE_NONLINEAR_SEQUENTIAL_SOLVER_H_

// Sequential linearisation (nup-algorithms.md §6.4, [KL] §V-D/E): a nonlinear problem is
// solved as a sequence of linear (LTV) NUP problems, each linearised around the previous
// plan. The inner problems run on one core Session, so the NUP state (variances, active
// sets) carries from one linearisation to the next and later subproblems settle in a few
// passes.
//
// A local method (Gauss-Newton / sequential convex programming, no second-order terms):
// it converges where the linearised model describes the plant well around the optimum.
// An optimum at a turning point of the model (a saturating actuator driven to its peak)
// may stall or cycle; the summary then says converged = false. Damping and trust regions
// (TrustRegion in nonlinear_model.h) keep steps inside the linearisation's validity.
//
// What is nonlinear is told by a Linearisation: a nonlinear plant model
// (core/nonlinear/nonlinear_model.h) or keep-out regions on a linear plant
// (core/nonlinear/keep_out.h).

#include <memory>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "core/options.h"
#include "core/problem.h"
#include "core/public/standalone/step_control.h"
#include "core/session/session.h"
#include "core/solution.h"

namespace nupmpc::core {

// Writes the LTV model (and anything else that depends on the linearisation point) of one
// nonlinear problem into a Problem of fixed shape.
class Linearisation {
 public:
  virtual ~Linearisation() = default;
  // The problem's shape and everything that does not depend on the linearisation point
  // (priors, x[0], terminal cost). Its time-varying fields are sized but unset.
  virtual const Problem& shape() const = 0;
  // Overwrites `problem`'s point-dependent fields with the linearisation around `point`.
  virtual void Linearise(const Solution& point, Problem* problem) const = 0;
  // How far a plan of the linearised problem is from solving the nonlinear one: the
  // largest model defect |x[n+1] - f(x[n], u[n])| or nonlinear constraint violation.
  virtual double NonlinearViolation(const Solution& plan) const = 0;
  // Replaces the point-independent part (priors, x[0], terminal cost, and the plant's
  // matrices where they are not linearised) with `base`'s: a problem in the caller's terms,
  // of the shape the linearisation was made for. Validated first; a rejected base leaves
  // the linearisation as it was.
  virtual absl::Status SetBase(const Problem& base) = 0;
  // Multiplies the proximal terms' standard deviations (TrustRegion in nonlinear_model.h)
  // by `scale` from the next Linearise() on: the sequential solver's step control. A
  // linearisation without proximal terms ignores it.
  virtual void SetProximalScale(double /*scale*/) {}
};

struct SequentialOptions {
  int max_linearisations = 100;
  // Message-passing iterations per linearised problem; 0 runs each to convergence (a
  // sequential convex program). [KL] re-linearises after every IAKE pass (1).
  int inner_iterations = 0;
  // Converged when the plan moved less than this between linearisations (max-norm over
  // states and inputs, relative to 1 + the plan's max-norm) and the last inner solve
  // converged.
  double step_tolerance = 1e-6;
  // The next linearisation point is point + damping·(plan - point); 1 takes the plan.
  double damping = 1.0;
  // Step control for linearisations with proximal terms (Levenberg-Marquardt): after a
  // linearised problem solved to convergence, the terms' standard deviations grow by
  // `proximal_growth` (up to `proximal_max_scale` times their initial size), so steps
  // lengthen while the linear models keep predicting well; when one does not converge
  // within the iteration cap (typically a linearisation that promises too much, or an
  // infeasible one), its plan is discarded and the point re-linearised with the
  // deviations divided by `proximal_shrink`. 1, 1, 1 keeps them fixed.
  double proximal_growth = 1.0;
  double proximal_max_scale = 1.0;
  double proximal_shrink = 1.0;
  // A plan is also discarded when its nonlinear violation exceeds both the floor and
  // `proximal_model_error` times the step (max-norm change of states and inputs), unless
  // it halved the last accepted plan's violation. Step control needs inner solves run to
  // convergence (inner_iterations = 0) and is off while proximal_shrink = 1. The rules are
  // StepControl's (core/public/standalone/step_control.h, shared with the client's
  // NonlinearSession); an inner solve stopped because Solve()'s max_iterations for the
  // whole sequence ran out is judged by its violation alone.
  double proximal_violation_floor = 1e-6;
  double proximal_model_error = 0.1;
};
absl::Status Validate(const SequentialOptions& options);
// The proximal_* fields as the step-control rules shared with the client.
StepControl StepControlOf(const SequentialOptions& options);

struct SequentialSummary {
  bool converged = false;
  int linearisations = 0;
  int inner_iterations = 0;     ///< message-passing passes over all linearisations
  int rejected = 0;             ///< linearisations whose plan the step control discarded
  double proximal_scale = 1.0;  ///< the proximal terms' scale at the end
  double last_step = 0.0;       ///< relative plan change at the last linearisation
  double nonlinear_violation = 0.0;
  SolveSummary last_inner;  ///< the last linearised problem's summary
  // Some linearised problem of this Solve() produced a plan (for the current x[0]): the
  // returned plan is then the last such one (or the last the step control accepted).
  bool has_plan = false;
  double solve_seconds = 0.0;
};

class SequentialSolver {
 public:
  static absl::StatusOr<std::unique_ptr<SequentialSolver>> Create(std::unique_ptr<Linearisation> linearisation,
                                                                  SolverOptions solver_options = {},
                                                                  SequentialOptions options = {});

  // Starts from `initial_guess` (states (N+1)×M, inputs N×L; outputs are recomputed by
  // the linearisation), writes the final plan to `plan`. `limits` apply to the whole
  // sequence: max_iterations caps the passes over all linearisations (0: only the options'
  // caps), the time limit and the cancel flag are checked in every pass, and warm_start
  // lets the first linearised problem continue the NUP state of the previous Solve() (later
  // ones always continue from the one before).
  absl::StatusOr<SequentialSummary> Solve(const Solution& initial_guess, Solution* plan,
                                          const SolveLimits& limits = {});

  // Between solves, for sessions (core/nonlinear/keep_out_session.h):
  absl::Status SetInitialState(const Eigen::VectorXd& x0);
  absl::Status SetBase(const Problem& base);  // see Linearisation::SetBase
  void ShiftWarmStart() { session_->ShiftWarmStart(); }
  void ReleaseWorkspace() { session_->ReleaseWorkspace(); }
  // Snapshots: the inner session's (its last linearised problem and the NUP state the next
  // Solve()'s first linearisation continues). The linearisation's own problem needs none:
  // SetBase and SetInitialState give it, and every linearisation rewrites the rest.
  absl::Status SaveState(std::string* out) { return session_->SaveState(out); }
  absl::Status RestoreState(std::string_view bytes) { return session_->RestoreState(bytes); }
  Algorithm algorithm() const { return session_->algorithm(); }

  const Problem& linearised_problem() const { return problem_; }

 private:
  SequentialSolver(std::unique_ptr<Linearisation> linearisation, SequentialOptions options, Problem problem)
      : linearisation_(std::move(linearisation)), options_(options), problem_(std::move(problem)) {}

  bool StepControlActive() const;
  // `step`: the max-norm change of states and inputs from point_ to plan_.
  bool StepControlRejects(const SequentialSummary& summary, double violation, double step, const SolveLimits& limits,
                          double accepted_violation) const;

  std::unique_ptr<Linearisation> linearisation_;
  SequentialOptions options_;
  Problem problem_;  ///< the current linearisation
  std::unique_ptr<Session> session_;
  Solution point_, plan_, trial_;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_NONLINEAR_SEQUENTIAL_SOLVER_H_
