#include "core/nonlinear/sequential_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>

#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

// The starting point of Create(): x[0] held, inputs zero. Only used to get a valid first
// linearisation (the session needs one); Solve() relinearises around the caller's guess.
Solution RestingPoint(const Problem& shape) {
  Solution point;
  point.inputs = Eigen::MatrixXd::Zero(shape.horizon, shape.num_inputs);
  point.states = shape.initial_mean.transpose().replicate(shape.horizon + 1, 1);
  point.outputs = Eigen::MatrixXd::Zero(shape.horizon + 1, shape.num_outputs);
  return point;
}

double MaxAbs(const Eigen::MatrixXd& m) { return m.size() == 0 ? 0.0 : m.cwiseAbs().maxCoeff(); }

// Max-norm change of states and inputs from `point` to `plan`, and the same relative to
// 1 + the plan's max-norm.
double AbsoluteStep(const Solution& point, const Solution& plan) {
  return std::max(MaxAbs(plan.states - point.states), MaxAbs(plan.inputs - point.inputs));
}
double RelativeStep(double absolute_step, const Solution& plan) {
  return absolute_step / (1.0 + std::max(MaxAbs(plan.states), MaxAbs(plan.inputs)));
}

}  // namespace

StepControl StepControlOf(const SequentialOptions& options) {
  return StepControl{options.proximal_growth, options.proximal_max_scale, options.proximal_shrink,
                     options.proximal_model_error, options.proximal_violation_floor};
}

bool SequentialSolver::StepControlActive() const {
  return StepControlOf(options_).active() && options_.inner_iterations == 0;
}

// Step control (SequentialOptions.proximal_*, the rules of step_control.h): the plan's
// nonlinear violation is the linear model's error over the step, second order in it. An
// inner solve that stopped because the caller's iteration budget ran out did not hit the
// linearisation's own cap.
bool SequentialSolver::StepControlRejects(const SequentialSummary& summary, double violation, double step,
                                          const SolveLimits& limits, double accepted_violation) const {
  if (!StepControlActive()) return false;
  const bool budget_spent = limits.max_iterations > 0 && summary.inner_iterations >= limits.max_iterations;
  const StepTrial trial{summary.last_inner.status == SolveStatus::kIterationLimit && !budget_spent, violation, step};
  return StepControlOf(options_).Rejects(trial, accepted_violation);
}

absl::Status Validate(const SequentialOptions& options) {
  if (options.max_linearisations < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("SequentialOptions.max_linearisations: must be ≥ 1, got ", options.max_linearisations));
  }
  if (options.inner_iterations < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("SequentialOptions.inner_iterations: must be ≥ 0, got ", options.inner_iterations));
  }
  if (!(options.step_tolerance > 0.0) || !std::isfinite(options.step_tolerance)) {
    return absl::InvalidArgumentError(
        absl::StrCat("SequentialOptions.step_tolerance: must be finite and > 0, got ", options.step_tolerance));
  }
  if (!(options.damping > 0.0 && options.damping <= 1.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("SequentialOptions.damping: must be in (0, 1], got ", options.damping));
  }
  if (const std::optional<StepControlError> bad = StepControlOf(options).FirstInvalid(); bad.has_value()) {
    return absl::InvalidArgumentError(
        absl::StrCat("SequentialOptions.proximal_", bad->field, ": ", bad->requirement, ", got ", bad->value));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<SequentialSolver>> SequentialSolver::Create(std::unique_ptr<Linearisation> linearisation,
                                                                           SolverOptions solver_options,
                                                                           SequentialOptions options) {
  if (linearisation == nullptr) return absl::InvalidArgumentError("linearisation: must not be null");
  NUPMPC_RETURN_IF_ERROR(Validate(options));
  Problem problem = linearisation->shape();
  if (problem.initial_mean.size() != problem.num_states) {
    return absl::InvalidArgumentError(absl::StrCat("Problem.initial_mean: expected size ", problem.num_states, ", got ",
                                                   problem.initial_mean.size()));
  }
  linearisation->Linearise(RestingPoint(problem), &problem);
  std::unique_ptr<SequentialSolver> solver(new SequentialSolver(std::move(linearisation), options, problem));
  NUPMPC_ASSIGN_OR_RETURN(solver->session_, Session::Create(std::move(problem), solver_options));
  return solver;
}

absl::Status SequentialSolver::SetInitialState(const Eigen::VectorXd& x0) {
  NUPMPC_RETURN_IF_ERROR(CheckInitialState(problem_, x0));
  problem_.initial_mean = x0;
  return absl::OkStatus();
}

absl::Status SequentialSolver::SetBase(const Problem& base) {
  NUPMPC_RETURN_IF_ERROR(linearisation_->SetBase(base));
  // The point-dependent fields are rewritten by the next Solve()'s first linearisation.
  problem_ = linearisation_->shape();
  return absl::OkStatus();
}

absl::StatusOr<SequentialSummary> SequentialSolver::Solve(const Solution& initial_guess, Solution* plan,
                                                          const SolveLimits& limits) {
  NUPMPC_RETURN_IF_ERROR(Validate(limits));
  const int N = problem_.horizon;
  if (initial_guess.states.rows() != N + 1 || initial_guess.states.cols() != problem_.num_states) {
    return absl::InvalidArgumentError(absl::StrCat("initial_guess.states: expected ", N + 1, "x", problem_.num_states,
                                                   ", got ", initial_guess.states.rows(), "x",
                                                   initial_guess.states.cols()));
  }
  if (initial_guess.inputs.rows() != N || initial_guess.inputs.cols() != problem_.num_inputs) {
    return absl::InvalidArgumentError(absl::StrCat("initial_guess.inputs: expected ", N, "x", problem_.num_inputs,
                                                   ", got ", initial_guess.inputs.rows(), "x",
                                                   initial_guess.inputs.cols()));
  }
  if (!initial_guess.states.allFinite() || !initial_guess.inputs.allFinite()) {
    return absl::InvalidArgumentError("initial_guess: contains a non-finite number");
  }
  const auto start = std::chrono::steady_clock::now();
  point_ = initial_guess;
  SolveLimits inner = limits;
  SequentialSummary summary;
  // Every Solve() starts the step control afresh.
  double proximal_scale = 1.0;
  linearisation_->SetProximalScale(proximal_scale);
  // The last plan the step control accepted, and its nonlinear violation (the guess's is
  // not known: the first plan is accepted unless its inner solve failed).
  std::optional<Solution> accepted;
  double accepted_violation = kInfinity;
  for (int k = 0; k < options_.max_linearisations; ++k) {
    // The limits are for the whole sequence: each inner solve gets what is left.
    inner.max_iterations = options_.inner_iterations;
    if (limits.max_iterations > 0) {
      const int left = limits.max_iterations - summary.inner_iterations;
      if (left <= 0) break;
      inner.max_iterations = inner.max_iterations > 0 ? std::min(inner.max_iterations, left) : left;
    }
    if (limits.time_limit_seconds > 0.0) {
      const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (elapsed >= limits.time_limit_seconds) break;
      inner.time_limit_seconds = limits.time_limit_seconds - elapsed;
    }
    // The first linearisation continues the previous Solve()'s NUP state if asked to;
    // later ones always continue the one before.
    inner.warm_start = k > 0 || limits.warm_start;
    linearisation_->Linearise(point_, &problem_);
    if (absl::Status updated = session_->Update(problem_); !updated.ok()) {
      // Typically a plan that left the model's domain (a Jacobian became non-finite).
      return absl::Status(updated.code(),
                          absl::StrCat("linearisation ", k, " around the previous plan: ", updated.message()));
    }
    // Into trial_: an inner solve without a plan leaves plan_ (this sequence's last) as it was.
    NUPMPC_ASSIGN_OR_RETURN(summary.last_inner, session_->Solve(inner, &trial_));
    ++summary.linearisations;
    summary.inner_iterations += summary.last_inner.iterations;
    if (!summary.last_inner.has_plan) break;
    std::swap(plan_, trial_);
    summary.has_plan = true;
    const double violation = StepControlActive() ? linearisation_->NonlinearViolation(plan_) : 0.0;
    const double step = AbsoluteStep(point_, plan_);
    if (StepControlRejects(summary, violation, step, limits, accepted_violation)) {
      // The linear model promised too much: keep the point, shorten the step.
      ++summary.rejected;
      proximal_scale = StepControlOf(options_).Shrunk(proximal_scale);
      linearisation_->SetProximalScale(proximal_scale);
      continue;
    }
    if (StepControlActive()) {
      accepted = plan_;
      accepted_violation = violation;
    }
    summary.last_step = RelativeStep(step, plan_);
    const bool inner_done = options_.inner_iterations > 0 || summary.last_inner.status == SolveStatus::kConverged;
    if (summary.last_inner.status == SolveStatus::kConverged && proximal_scale < options_.proximal_max_scale) {
      proximal_scale = StepControlOf(options_).Grown(proximal_scale);
      linearisation_->SetProximalScale(proximal_scale);
    }
    if (options_.damping < 1.0 && summary.last_step > options_.step_tolerance) {
      point_.states += options_.damping * (plan_.states - point_.states);
      point_.inputs += options_.damping * (plan_.inputs - point_.inputs);
    } else {
      point_ = plan_;
    }
    // Under step control a damped step is small because it is damped (StepControl::ToleranceFactor).
    if (inner_done &&
        summary.last_step <= options_.step_tolerance * StepControlOf(options_).ToleranceFactor(proximal_scale)) {
      summary.converged = true;
      break;
    }
    // A time limit or a cancel inside the inner solve ends the sequence too.
    if (summary.last_inner.status == SolveStatus::kTimeLimit || summary.last_inner.status == SolveStatus::kCancelled) {
      break;
    }
  }
  if (summary.linearisations == 0) {
    return absl::DeadlineExceededError("no time or iterations left for a first linearisation");
  }
  // A rejected last step is not the answer.
  if (accepted.has_value()) plan_ = *std::move(accepted);
  summary.proximal_scale = proximal_scale;
  summary.solve_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!summary.has_plan) {
    // No linearised problem of this call produced a plan (stopped, or broke down, in the
    // first one): nothing to return, the next call starts from the caller's guess again.
    summary.nonlinear_violation = std::numeric_limits<double>::quiet_NaN();
    if (plan != nullptr) *plan = Solution{};
    return summary;
  }
  summary.nonlinear_violation = linearisation_->NonlinearViolation(plan_);
  if (plan != nullptr) *plan = plan_;
  return summary;
}

}  // namespace nupmpc::core
