#include "core/session/session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <utility>

#include "core/algorithms/outer_iteration.h"
#include "core/algorithms/select.h"
#include "core/priors/scalar_rules.h"
#include "core/session/discrete_search.h"
#include "core/session/elastic.h"
#include "core/session/footprint.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

// Largest input change between passes (relative to 1 + the largest input) at which a
// problem with non-convex priors counts as settled.
constexpr double kNonconvexStepTolerance = 1e-9;

bool AnyInputConstrained(const Problem& p) {
  for (const ScalarPrior& prior : p.input_priors) {
    if (prior.kind != PriorKind::kNone) return true;
  }
  return false;
}

bool AnyNonconvexPrior(const Problem& p) {
  const auto nonconvex = [](const ScalarPrior& prior) { return IsNonconvex(prior.kind); };
  return std::any_of(p.input_priors.begin(), p.input_priors.end(), nonconvex) ||
         std::any_of(p.output_priors.begin(), p.output_priors.end(), nonconvex);
}

bool AnyBinaryInput(const Problem& p) {
  return std::any_of(p.input_priors.begin(), p.input_priors.end(),
                     [](const ScalarPrior& prior) { return prior.kind == PriorKind::kBinary; });
}

}  // namespace

// The session's loop and algorithm as the discrete search and the elastic fallback see them.
class Session::Hooks final : public DiscreteSearch::PinnedPasses, public ElasticFallback::Solve {
 public:
  explicit Hooks(Session* session) : s_(*session) {}

  void Pin(int index, double value) override { s_.algorithm_->input_pinning()->PinInput(index, value); }
  void ReleasePins() override { s_.algorithm_->input_pinning()->ReleaseInputPins(); }
  bool Run(SolveSummary* summary, PrimalIterate* out) override {
    s_.algorithm_->Iterate(out);
    if (s_.PassInterrupted(summary)) return false;
    ++summary->iterations;
    return true;
  }

  Problem* mutable_problem() override { return &s_.problem_; }
  void OutputPriorsChanged() override {
    s_.algorithm_->RefreshOutputPriors(s_.problem_);
    s_.evaluator_.Prepare(s_.problem_);
  }
  void ColdStart() override { s_.algorithm_->ColdStart(); }
  SolveSummary RunLoop(const SolveLimits& limits, bool warm) override { return s_.RunLoop(limits, warm); }
  ObjectiveEvaluator::Result EvaluatePlan() override { return s_.evaluator_.Evaluate(s_.problem_, s_.best_); }

 private:
  Session& s_;
};

Session::Session(Problem problem, SolverOptions options) : problem_(std::move(problem)), options_(options) {}

Session::~Session() = default;

Algorithm Session::algorithm() const { return algorithm_->algorithm(); }

void Session::ReleaseWorkspace() { algorithm_->ReleaseWorkspace(); }

absl::StatusOr<std::unique_ptr<Session>> Session::Create(Problem problem, SolverOptions options) {
  NUPMPC_RETURN_IF_ERROR(Validate(problem));
  NUPMPC_RETURN_IF_ERROR(Validate(options));
  std::unique_ptr<Session> session(new Session(std::move(problem), options));
  NUPMPC_RETURN_IF_ERROR(session->Rebuild());
  return session;
}

absl::Status Session::Rebuild() {
  NUPMPC_ASSIGN_OR_RETURN(algorithm_, MakeOuterIteration(problem_, options_));
  evaluator_.Prepare(problem_);
  current_.Resize(problem_.num_states, problem_.num_inputs, problem_.horizon);
  candidate_.Resize(problem_.num_states, problem_.num_inputs, problem_.horizon);
  best_.Resize(problem_.num_states, problem_.num_inputs, problem_.horizon);
  least_violation_.Resize(problem_.num_states, problem_.num_inputs, problem_.horizon);
  has_warm_state_ = false;
  DerivePriorFlags();
  return absl::OkStatus();
}

void Session::DerivePriorFlags() {
  has_binary_inputs_ = AnyBinaryInput(problem_);
  has_nonconvex_priors_ = AnyNonconvexPrior(problem_);
  elastic_.Derive(problem_, options_, algorithm_->algorithm());
  flops_per_step_ = EstimateFootprint(ShapeOf(problem_, algorithm_->algorithm())).flops_per_step;
}

absl::Status Session::SetInitialState(const Eigen::VectorXd& x0) {
  NUPMPC_RETURN_IF_ERROR(CheckInitialState(problem_, x0));
  problem_.initial_mean = x0;
  algorithm_->RefreshInitialState(problem_);
  return absl::OkStatus();
}

absl::Status Session::Update(const Problem& problem) {
  NUPMPC_RETURN_IF_ERROR(CheckSameShape(problem_, problem));
  NUPMPC_RETURN_IF_ERROR(Validate(problem));
  const bool was_input_constrained = AnyInputConstrained(problem_);
  Problem previous = std::exchange(problem_, problem);
  if (absl::Status adopted = AdoptNewValues(was_input_constrained); !adopted.ok()) {
    problem_ = std::move(previous);
    return adopted;
  }
  return absl::OkStatus();
}

absl::Status Session::Apply(const StepUpdate& update) {
  NUPMPC_RETURN_IF_ERROR(RefusePreviousInput(update));
  NUPMPC_RETURN_IF_ERROR(RefuseReference(update));
  if (update.state.has_value()) NUPMPC_RETURN_IF_ERROR(CheckStepState(problem_.num_states, *update.state));
  if (!update.changes_priors() && !update.changes_model()) {
    // The common per-step path: only x[0] changes.
    return update.state.has_value() ? SetInitialState(*update.state) : absl::OkStatus();
  }
  if (update.changes_priors()) {
    NUPMPC_RETURN_IF_ERROR(CheckPriorChanges(problem_.num_inputs, problem_.num_outputs, problem_.horizon, update));
  }
  if (update.changes_model()) NUPMPC_RETURN_IF_ERROR(CheckModelChanges(problem_, update.model));
  // The candidates are written into scratch arrays of the same size (no allocation after
  // the first update, unless a term becomes per-step) and swapped in; the swap leaves the
  // previous ones in scratch.
  if (update.changes_priors()) {
    scratch_input_priors_ = problem_.input_priors;
    scratch_output_priors_ = problem_.output_priors;
    WritePriorChanges(update, problem_.num_inputs, problem_.num_outputs, problem_.horizon, &scratch_input_priors_,
                      &scratch_output_priors_);
  }
  const bool new_storage = update.changes_model() && ModelChangesStorage(problem_, update.model);
  if (update.changes_model()) {
    CopyModelTerms(problem_, &scratch_model_);
    WriteModelChanges(update.model, problem_, &scratch_model_);
  }
  const bool was_input_constrained = AnyInputConstrained(problem_);
  const auto swap_candidate = [&] {
    if (update.changes_priors()) {
      problem_.input_priors.swap(scratch_input_priors_);
      problem_.output_priors.swap(scratch_output_priors_);
    }
    if (update.changes_model()) SwapModelTerms(&problem_, &scratch_model_);
    if (update.state.has_value()) problem_.initial_mean.swap(scratch_state_);
  };
  if (update.state.has_value()) scratch_state_ = *update.state;
  swap_candidate();
  // Each new prior was checked by CheckPriorChanges and a shift only moves checked ones;
  // the model terms by CheckModelChanges: what is left is how the new priors combine.
  absl::Status adopted = update.changes_priors() ? CheckPriorGrouping(problem_) : absl::OkStatus();
  if (adopted.ok()) adopted = AdoptNewValues(was_input_constrained, new_storage);
  if (!adopted.ok()) swap_candidate();  // the previous values again
  return adopted;
}

absl::Status Session::AdoptNewValues(bool was_input_constrained, bool new_storage) {
  NUPMPC_ASSIGN_OR_RETURN(const Algorithm selected, SelectAlgorithm(problem_, options_.algorithm));
  // IFFBDD's graph is augmented iff some input is constrained: that is part of its shape;
  // so is the storage of the model (one or per-step matrices).
  const bool same_graph = !new_storage && selected == algorithm_->algorithm() &&
                          (selected != Algorithm::kIffbdd || AnyInputConstrained(problem_) == was_input_constrained);
  if (same_graph) {
    algorithm_->Refresh(problem_);
  } else {
    SolverOptions forced = options_;
    forced.algorithm = selected;
    NUPMPC_ASSIGN_OR_RETURN(algorithm_, MakeOuterIteration(problem_, forced));
    has_warm_state_ = false;
  }
  evaluator_.Prepare(problem_);
  DerivePriorFlags();
  return absl::OkStatus();
}

bool Session::PassInterrupted(SolveSummary* summary) {
  if (!interrupt_->fired()) return false;
  summary->status = *interrupt_->reason();
  pass_interrupted_ = true;
  return true;
}

void Session::ShiftWarmStart() {
  if (!has_warm_state_) return;
  algorithm_->ShiftWarmStart();
  // The carried primal iterate moves too (the first pass's settling test compares with it).
  const int N = problem_.horizon;
  for (int n = 0; n + 1 < N; ++n) best_.u.col(n) = best_.u.col(n + 1);
}

void Session::ResetWarmStart() {
  algorithm_->ColdStart();
  has_warm_state_ = false;
}

absl::StatusOr<SolveSummary> Session::Solve(const SolveLimits& limits, Solution* solution) {
  NUPMPC_RETURN_IF_ERROR(Validate(limits));
  // The limits count from here: getting the workspace back after ReleaseWorkspace() may
  // recompute a carried policy (a backward pass), which polls the interrupt like any pass.
  const auto start = std::chrono::steady_clock::now();
  Interrupt interrupt(limits, start, flops_per_step_);
  interrupt_ = &interrupt;
  pass_interrupted_ = false;
  algorithm_->set_interrupt(&interrupt);
  const bool warm = limits.warm_start && has_warm_state_;
  if (!warm) algorithm_->ColdStart();
  algorithm_->AcquireWorkspace(problem_);
  const int max_iterations = IterationCap(limits);
  const bool elastic_possible = elastic_.applies() && options_.elastic_after_iterations < max_iterations;
  SolveLimits hard_limits = limits;
  if (elastic_possible) hard_limits.max_iterations = options_.elastic_after_iterations;
  SolveSummary summary;
  if (PassInterrupted(&summary)) {
    summary.has_plan = false;
  } else {
    summary = RunLoop(hard_limits, warm);
    // An empty constraint set found by the hard loop goes to the elastic form at once.
    const bool unsolved = summary.status == SolveStatus::kIterationLimit || summary.status == SolveStatus::kInfeasible;
    if (elastic_possible && unsolved &&
        summary.max_violation > options_.violation_tolerance * evaluator_.bound_scale()) {
      Hooks hooks(this);
      elastic_.Continue(&hooks, interrupt_, limits, max_iterations,
                        options_.violation_tolerance * evaluator_.bound_scale(), &summary);
    }
  }
  if (has_binary_inputs_ && summary.has_plan) {
    // The sequential fixing needs an algorithm that pins inputs (IAKE, the one that runs
    // binary priors); without one every binary is rounded at once.
    Hooks hooks(this);
    DiscreteSearch search(problem_, options_, &evaluator_, interrupt_, &best_, &current_);
    search.MakeInputsDiscrete(algorithm_->input_pinning() != nullptr ? &hooks : nullptr, &summary);
  }
  // A limit reached anywhere (also inside an evaluation of the discrete search) is the status.
  if (interrupt.fired()) summary.status = *interrupt.reason();
  // A cancelled solve returns no plan, whatever it got to (the caller gave up on it).
  if (summary.status == SolveStatus::kCancelled) summary.has_plan = false;
  summary.solve_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  summary.warm_started = warm;
  summary.algorithm = algorithm_->algorithm();
  // The elastic fallback's carried state belongs to the elastic problem, not this one; an
  // interrupted pass may have left the carried state half updated; an infeasible problem's
  // multipliers grew without bound.
  has_warm_state_ = summary.status != SolveStatus::kNumericalError && summary.status != SolveStatus::kInfeasible &&
                    !summary.elastic && !pass_interrupted_;
  if (!has_warm_state_) algorithm_->ColdStart();
  algorithm_->set_interrupt(nullptr);
  interrupt_ = nullptr;
  if (!summary.has_plan) {
    summary.objective = std::numeric_limits<double>::quiet_NaN();
    summary.max_violation = std::numeric_limits<double>::quiet_NaN();
  }
  if (solution != nullptr) {
    if (summary.has_plan) {
      evaluator_.Evaluate(problem_, best_);  // not interrupted: the returned plan's trajectories
      solution->inputs = best_.u.transpose();
      solution->states = evaluator_.states().transpose();
      solution->outputs = evaluator_.outputs().transpose();
    } else {
      *solution = Solution{};  // no plan: every matrix empty
    }
  }
  return summary;
}

int Session::IterationCap(const SolveLimits& limits) const {
  return limits.max_iterations > 0 ? std::min(limits.max_iterations, options_.max_iterations) : options_.max_iterations;
}

SolveSummary Session::RunLoop(const SolveLimits& limits, bool warm) {
  const int max_iterations = IterationCap(limits);
  const double violation_tolerance = options_.violation_tolerance * evaluator_.bound_scale();
  const bool polish_enabled = options_.polish_after_stable_iterations > 0;

  SolveSummary summary;
  summary.status = SolveStatus::kIterationLimit;
  bool have_finite = false;  ///< best_ holds a complete, finite iterate of this loop
  // The plain iterate of this loop closest to the bounds, returned if the loop finds them
  // contradictory (the last iterate has then diverged with the multipliers).
  double least_violation = kInfinity, least_violation_objective = 0.0;
  infeasibility_.Start();

  const auto stop_requested = [&]() { return StopNow(interrupt_, &summary); };
  // After an evaluation: a pass the interrupt cut short there is neither returned nor
  // counted (the plan returned is the previous pass's, as a solve capped there returns it).
  const auto evaluation_cut_short = [&]() {
    if (!interrupt_->fired()) return false;
    --summary.iterations;
    return true;
  };

  // Tries the active-set polish (1 + polish_rounds passes, more up to polish_max_rounds
  // while the deciding residual keeps falling); true if it was accepted.
  const auto try_polish = [&]() {
    double best_residual = kInfinity;
    for (int round = 0; summary.iterations < max_iterations; ++round) {
      if (round > 0 && stop_requested()) return false;  // up to 13 passes: honour the limits
      const double residual = algorithm_->Polish(&candidate_);
      if (PassInterrupted(&summary)) return false;  // an incomplete pass: discarded
      ++summary.iterations;
      if (limits.trace) {
        limits.trace({.kind = PassTrace::Kind::kPolish, .pass = summary.iterations, .residual = residual});
      }
      const bool progress = residual < best_residual;
      best_residual = std::min(best_residual, residual);
      if (residual <= violation_tolerance && AllFinite(candidate_)) {
        const ObjectiveEvaluator::Result r = evaluator_.Evaluate(problem_, candidate_, interrupt_);
        if (evaluation_cut_short()) return false;  // not evaluated: not accepted
        if (std::isfinite(r.objective) && r.max_violation <= violation_tolerance) {
          std::swap(best_, candidate_);
          algorithm_->AcceptPolishRegions();
          summary.objective = r.objective;
          summary.max_violation = r.max_violation;
          summary.polished = true;
          summary.has_plan = true;
          summary.status = SolveStatus::kConverged;
          return true;
        }
      }
      if (!have_finite && AllFinite(candidate_)) {
        // Not verified, but a complete pass of this solve for this x[0]: until a plain
        // iterate exists, the solve's plan (a warm solve capped at one pass returns it).
        const ObjectiveEvaluator::Result r = evaluator_.Evaluate(problem_, candidate_, interrupt_);
        if (evaluation_cut_short()) return false;
        if (std::isfinite(r.objective) && std::isfinite(r.max_violation)) {
          std::swap(best_, candidate_);
          have_finite = true;
          summary.objective = r.objective;
          summary.max_violation = r.max_violation;
        }
      }
      const bool keep_going = round < options_.polish_rounds || (progress && round < options_.polish_max_rounds);
      if (!keep_going) break;
    }
    return false;
  };

  // A warm start carries the previous active set: if it is still right, one exact pass
  // finishes the solve (restarting from the optimum takes one iteration).
  if (warm && polish_enabled && algorithm_->has_regions() && !stop_requested()) {
    algorithm_->AdoptCarriedRegionsForPolish();
    if (try_polish()) return summary;
  }

  double previous_objective = std::numeric_limits<double>::quiet_NaN();
  int stable = 0;
  int polish_wait = options_.polish_after_stable_iterations;
  // Whether `changed` region changes count as a settled active set. Which fraction applies
  // depends on the next polish (NextPolishSolvesInputsOnly scans every row): asked only
  // when the two fractions disagree about `changed`.
  const auto settled = [&](int changed) {
    const double scalars = algorithm_->decided_scalars();
    const double inputs_only = options_.input_polish_settled_fraction * scalars;
    const double whole = options_.polish_settled_fraction * scalars;
    if (changed <= std::min(inputs_only, whole)) return true;
    if (changed > std::max(inputs_only, whole)) return false;
    return changed <= (algorithm_->NextPolishSolvesInputsOnly() ? inputs_only : whole);
  };
  while (summary.iterations < max_iterations) {
    if (stop_requested()) break;
    const int changed = algorithm_->Iterate(&current_);
    if (PassInterrupted(&summary)) break;  // an incomplete pass: discarded
    ++summary.iterations;
    const ObjectiveEvaluator::Result r = AllFinite(current_) ? evaluator_.Evaluate(problem_, current_, interrupt_)
                                                             : ObjectiveEvaluator::Result{NAN, NAN};
    if (evaluation_cut_short()) {  // a complete pass, not evaluated: not returned either
      summary.status = *interrupt_->reason();
      break;
    }
    if (!std::isfinite(r.objective) || !std::isfinite(r.max_violation)) {
      summary.status = SolveStatus::kNumericalError;
      break;
    }
    // Non-convex priors (NUV, binary) leave no trace in J (§5.1): J alone can sit still
    // while the inputs are still being sparsified or binarised, so the plan must settle
    // too.
    const bool iterate_settled =
        !has_nonconvex_priors_ || (current_.u - best_.u).cwiseAbs().maxCoeff() <=
                                      kNonconvexStepTolerance * (1.0 + current_.u.cwiseAbs().maxCoeff());
    if (limits.trace) {
      limits.trace({.kind = PassTrace::Kind::kIterate,
                    .pass = summary.iterations,
                    .changed = changed,
                    .objective = r.objective,
                    .max_violation = r.max_violation});
    }
    std::swap(best_, current_);
    have_finite = true;
    summary.objective = r.objective;
    summary.max_violation = r.max_violation;
    const bool objective_settled = iterate_settled && std::abs(r.objective - previous_objective) <=
                                                          options_.objective_tolerance * std::abs(r.objective);
    if (objective_settled && r.max_violation <= violation_tolerance) {
      summary.status = SolveStatus::kConverged;
      break;
    }
    if (r.max_violation <= least_violation) {  // ties: the later, further converged one
      least_violation = r.max_violation;
      least_violation_objective = r.objective;
      least_violation_.x0 = best_.x0;  // same sizes: no allocation
      least_violation_.u = best_.u;
    }
    if (infeasibility_.Observe(algorithm_->largest_dual(), r.max_violation, objective_settled, violation_tolerance)) {
      std::swap(best_, least_violation_);
      summary.objective = least_violation_objective;
      summary.max_violation = least_violation;
      summary.status = SolveStatus::kInfeasible;
      break;
    }
    previous_objective = r.objective;

    stable = changed >= 0 && settled(changed) ? stable + 1 : 0;
    if (polish_enabled && changed >= 0 && stable >= polish_wait) {
      algorithm_->AdoptRegionsForPolish();
      if (try_polish()) break;
      if (interrupt_->fired()) break;
      // The active set was not right yet: wait longer before the next attempt.
      stable = 0;
      polish_wait = std::min(2 * polish_wait + 1, 64);
    }
  }
  // No iterate of this solve survived (limits hit first, or a breakdown): best_ is a
  // previous solve's plan, for another x[0], and is never reported as a plan.
  summary.has_plan = have_finite || summary.polished;
  return summary;
}

}  // namespace nupmpc::core
