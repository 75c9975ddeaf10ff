#include "core/session/solve_loop.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "core/algorithms/outer_iteration.h"
#include "core/priors/scalar_prior.h"

namespace nupmpc::core {
namespace {

// Largest input change between passes (relative to 1 + the largest input) at which a
// problem with non-convex priors counts as settled.
constexpr double kNonconvexStepTolerance = 1e-9;

}  // namespace

bool PassInterrupted(const Interrupt& interrupt, SolveSummary* summary, bool* pass_interrupted) {
  if (!interrupt.fired()) return false;
  summary->status = *interrupt.reason();
  *pass_interrupted = true;
  return true;
}

SolveLoop::SolveLoop(const SolveLoopParts& parts, const SolveLimits& limits, int max_iterations)
    : p_(parts),
      limits_(limits),
      max_iterations_(max_iterations),
      violation_tolerance_(parts.options.violation_tolerance * parts.evaluator.bound_scale()),
      polish_enabled_(parts.options.polish_after_stable_iterations > 0),
      least_violation_(kInfinity),
      previous_objective_(std::numeric_limits<double>::quiet_NaN()),
      polish_wait_(parts.options.polish_after_stable_iterations) {}

SolveSummary SolveLoop::Run(bool warm) {
  summary_.status = SolveStatus::kIterationLimit;
  p_.infeasibility.Start();
  // A warm start carries the previous active set: if it is still right, one exact pass
  // finishes the solve (restarting from the optimum takes one iteration).
  if (warm && polish_enabled_ && p_.algorithm.has_regions() && !StopRequested()) {
    p_.algorithm.AdoptCarriedRegionsForPolish();
    if (TryPolish()) return summary_;
  }
  while (summary_.iterations < max_iterations_) {
    if (StopRequested() || !Pass()) break;
  }
  // No iterate of this solve survived (limits hit first, or a breakdown): best is a
  // previous solve's plan, for another x[0], and is never reported as a plan.
  summary_.has_plan = have_finite_ || summary_.polished;
  return summary_;
}

bool SolveLoop::StopRequested() { return StopNow(&p_.interrupt, &summary_); }

bool SolveLoop::PassInterrupted() { return core::PassInterrupted(p_.interrupt, &summary_, &p_.pass_interrupted); }

bool SolveLoop::EvaluationCutShort() {
  if (!p_.interrupt.fired()) return false;
  --summary_.iterations;
  return true;
}

bool SolveLoop::Pass() {
  const int changed = p_.algorithm.Iterate(&p_.current);
  if (PassInterrupted()) return false;  // an incomplete pass: discarded
  ++summary_.iterations;
  const ObjectiveEvaluator::Result r = AllFinite(p_.current)
                                           ? p_.evaluator.Evaluate(p_.problem, p_.current, &p_.interrupt)
                                           : ObjectiveEvaluator::Result{NAN, NAN};
  if (EvaluationCutShort()) {  // a complete pass, not evaluated: not returned either
    summary_.status = *p_.interrupt.reason();
    return false;
  }
  if (!std::isfinite(r.objective) || !std::isfinite(r.max_violation)) {
    summary_.status = SolveStatus::kNumericalError;
    return false;
  }
  const bool iterate_settled = IterateSettled();
  if (limits_.trace) {
    limits_.trace({.kind = PassTrace::Kind::kIterate,
                   .pass = summary_.iterations,
                   .changed = changed,
                   .objective = r.objective,
                   .max_violation = r.max_violation});
  }
  std::swap(p_.best, p_.current);
  have_finite_ = true;
  summary_.objective = r.objective;
  summary_.max_violation = r.max_violation;
  const bool objective_settled = iterate_settled && std::abs(r.objective - previous_objective_) <=
                                                        p_.options.objective_tolerance * std::abs(r.objective);
  if (objective_settled && r.max_violation <= violation_tolerance_) {
    summary_.status = SolveStatus::kConverged;
    return false;
  }
  KeepIfLeastViolation(r);
  if (p_.infeasibility.Observe(p_.algorithm.largest_dual(), r.max_violation, objective_settled, violation_tolerance_)) {
    std::swap(p_.best, p_.least_violation);
    summary_.objective = least_violation_objective_;
    summary_.max_violation = least_violation_;
    summary_.status = SolveStatus::kInfeasible;
    return false;
  }
  previous_objective_ = r.objective;
  return !PolishWhenSettled(changed);
}

bool SolveLoop::IterateSettled() const {
  // Non-convex priors (NUV, binary) leave no trace in J (§5.1): J alone can sit still
  // while the inputs are still being sparsified or binarised, so the plan must settle
  // too.
  return !p_.nonconvex_priors || (p_.current.u - p_.best.u).cwiseAbs().maxCoeff() <=
                                     kNonconvexStepTolerance * (1.0 + p_.current.u.cwiseAbs().maxCoeff());
}

void SolveLoop::KeepIfLeastViolation(const ObjectiveEvaluator::Result& r) {
  if (r.max_violation > least_violation_) return;  // ties: the later, further converged one
  least_violation_ = r.max_violation;
  least_violation_objective_ = r.objective;
  p_.least_violation.x0 = p_.best.x0;  // same sizes: no allocation
  p_.least_violation.u = p_.best.u;
}

bool SolveLoop::Settled(int changed) const {
  // Which fraction applies depends on the next polish (NextPolishSolvesInputsOnly scans
  // every row): asked only when the two fractions disagree about `changed`.
  const double scalars = p_.algorithm.decided_scalars();
  const double inputs_only = p_.options.input_polish_settled_fraction * scalars;
  const double whole = p_.options.polish_settled_fraction * scalars;
  if (changed <= std::min(inputs_only, whole)) return true;
  if (changed > std::max(inputs_only, whole)) return false;
  return changed <= (p_.algorithm.NextPolishSolvesInputsOnly() ? inputs_only : whole);
}

bool SolveLoop::PolishWhenSettled(int changed) {
  stable_ = changed >= 0 && Settled(changed) ? stable_ + 1 : 0;
  if (!polish_enabled_ || changed < 0 || stable_ < polish_wait_) return false;
  p_.algorithm.AdoptRegionsForPolish();
  if (TryPolish()) return true;
  if (p_.interrupt.fired()) return true;
  // The active set was not right yet: wait longer before the next attempt.
  stable_ = 0;
  polish_wait_ = std::min(2 * polish_wait_ + 1, 64);
  return false;
}

bool SolveLoop::TryPolish() {
  double best_residual = kInfinity;
  for (int round = 0; summary_.iterations < max_iterations_; ++round) {
    if (round > 0 && StopRequested()) return false;  // up to 13 passes: honour the limits
    const double residual = p_.algorithm.Polish(&p_.candidate);
    if (PassInterrupted()) return false;  // an incomplete pass: discarded
    ++summary_.iterations;
    if (limits_.trace) {
      limits_.trace({.kind = PassTrace::Kind::kPolish, .pass = summary_.iterations, .residual = residual});
    }
    const bool progress = residual < best_residual;
    best_residual = std::min(best_residual, residual);
    const Verdict verified = AcceptIfVerified(residual);
    if (verified == Verdict::kAccepted) return true;
    if (verified == Verdict::kCutShort || KeepIfFirstFinite() == Verdict::kCutShort) return false;
    const bool keep_going = round < p_.options.polish_rounds || (progress && round < p_.options.polish_max_rounds);
    if (!keep_going) break;
  }
  return false;
}

SolveLoop::Verdict SolveLoop::AcceptIfVerified(double residual) {
  if (!(residual <= violation_tolerance_) || !AllFinite(p_.candidate)) return Verdict::kRejected;  // NaN: rejected
  const ObjectiveEvaluator::Result r = p_.evaluator.Evaluate(p_.problem, p_.candidate, &p_.interrupt);
  if (EvaluationCutShort()) return Verdict::kCutShort;  // not evaluated: not accepted
  if (!std::isfinite(r.objective) || !(r.max_violation <= violation_tolerance_)) return Verdict::kRejected;
  std::swap(p_.best, p_.candidate);
  p_.algorithm.AcceptPolishRegions();
  summary_.objective = r.objective;
  summary_.max_violation = r.max_violation;
  summary_.polished = true;
  summary_.has_plan = true;
  summary_.status = SolveStatus::kConverged;
  return Verdict::kAccepted;
}

SolveLoop::Verdict SolveLoop::KeepIfFirstFinite() {
  if (have_finite_ || !AllFinite(p_.candidate)) return Verdict::kRejected;
  // Not verified, but a complete pass of this solve for this x[0]: until a plain iterate
  // exists, the solve's plan (a warm solve capped at one pass returns it).
  const ObjectiveEvaluator::Result r = p_.evaluator.Evaluate(p_.problem, p_.candidate, &p_.interrupt);
  if (EvaluationCutShort()) return Verdict::kCutShort;
  if (!std::isfinite(r.objective) || !std::isfinite(r.max_violation)) return Verdict::kRejected;
  std::swap(p_.best, p_.candidate);
  have_finite_ = true;
  summary_.objective = r.objective;
  summary_.max_violation = r.max_violation;
  return Verdict::kAccepted;
}

}  // namespace nupmpc::core
