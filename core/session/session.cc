#include "core/session/session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/algorithms/select.h"
#include "core/priors/scalar_rules.h"
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

bool AllFinite(const PrimalIterate& it) { return it.x0.allFinite() && it.u.allFinite(); }

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

std::optional<SolveStatus> LimitReached(const SolveLimits& limits, double elapsed_seconds) {
  if (limits.cancel != nullptr && limits.cancel->load(std::memory_order_relaxed)) return SolveStatus::kCancelled;
  if (limits.time_limit_seconds > 0.0 && elapsed_seconds >= limits.time_limit_seconds) return SolveStatus::kTimeLimit;
  return std::nullopt;
}

const char* SolveStatusName(SolveStatus status) {
  switch (status) {
    case SolveStatus::kConverged: return "converged";
    case SolveStatus::kIterationLimit: return "iteration_limit";
    case SolveStatus::kTimeLimit: return "time_limit";
    case SolveStatus::kNumericalError: return "numerical_error";
    case SolveStatus::kCancelled: return "cancelled";
    case SolveStatus::kInfeasible: return "infeasible";
  }
  return "unknown";
}

std::string SolveSummary::Describe() const {
  return absl::StrCat(AlgorithmName(algorithm), ": ", SolveStatusName(status), " after ", iterations, " iterations",
                      polished ? " (polished)" : "", elastic ? " (elastic)" : "", warm_started ? ", warm" : "", ", J = ", objective,
                      ", max violation = ", max_violation,
                      linearisations > 0 ? absl::StrCat(", ", linearisations, " linearisations, nonlinear violation = ",
                                                        nonlinear_violation)
                                         : "");
}

Session::Session(Problem problem, SolverOptions options)
    : problem_(std::move(problem)), options_(options) {}

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
  has_warm_state_ = false;
  DerivePriorFlags();
  return absl::OkStatus();
}

void Session::DerivePriorFlags() {
  has_binary_inputs_ = AnyBinaryInput(problem_);
  has_nonconvex_priors_ = AnyNonconvexPrior(problem_);
  FindHardOutputBounds(problem_, &hard_bounds_);
  elastic_applies_ = options_.elastic_slope > 0.0 && ElasticFormApplies(hard_bounds_, algorithm_->algorithm());
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
  if (!update.changes_priors()) {
    // The common per-step path: only x[0] changes.
    return update.state.has_value() ? SetInitialState(*update.state) : absl::OkStatus();
  }
  NUPMPC_RETURN_IF_ERROR(CheckPriorChanges(problem_.num_inputs, problem_.num_outputs, problem_.horizon, update));
  // The candidate priors are written into scratch arrays of the same size (no allocation
  // after the first update) and swapped in; the swap leaves the previous ones in scratch.
  scratch_input_priors_ = problem_.input_priors;
  scratch_output_priors_ = problem_.output_priors;
  WritePriorChanges(update, problem_.num_inputs, problem_.num_outputs, problem_.horizon, &scratch_input_priors_,
                    &scratch_output_priors_);
  const bool was_input_constrained = AnyInputConstrained(problem_);
  const auto swap_candidate = [&] {
    problem_.input_priors.swap(scratch_input_priors_);
    problem_.output_priors.swap(scratch_output_priors_);
    if (update.state.has_value()) problem_.initial_mean.swap(scratch_state_);
  };
  if (update.state.has_value()) scratch_state_ = *update.state;
  swap_candidate();
  absl::Status adopted = ValidatePriors(problem_);
  if (adopted.ok()) adopted = AdoptNewValues(was_input_constrained);
  if (!adopted.ok()) swap_candidate();  // the previous values again
  return adopted;
}

absl::Status Session::AdoptNewValues(bool was_input_constrained) {
  NUPMPC_ASSIGN_OR_RETURN(const Algorithm selected, SelectAlgorithm(problem_, options_.algorithm));
  // IFFBDD's graph is augmented iff some input is constrained: that is part of its shape.
  const bool same_graph =
      selected == algorithm_->algorithm() &&
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

double Session::RoundDiscreteStep(int n, bool pin) {
  double gap = 0.0;
  for (int first = 0; first < problem_.num_inputs; ++first) {
    const ScalarPrior& prior = problem_.input_prior(n, first);
    if (prior.kind != PriorKind::kBinary) continue;
    // An M-level group is rounded as its sum: the nearest level.
    const int last = GroupEnd(n, first);
    const double a = prior.lower, b = prior.upper;
    double sum = 0.0;
    for (int j = first; j <= last; ++j) sum += (best_.u(j, n) - a) / (b - a);
    const double high = std::clamp(std::round(sum), 0.0, static_cast<double>(last - first + 1));
    gap = std::max(gap, std::abs(sum - high) * std::abs(b - a));
    SetGroupLevel(n, first, last, static_cast<int>(high));
    for (int j = first; pin && j <= last; ++j) algorithm_->PinInput(n * problem_.num_inputs + j, best_.u(j, n));
    first = last;
  }
  return gap;
}

bool Session::StopNow(SolveSummary* summary) {
  if (!interrupt_->CheckNow()) return false;
  summary->status = *interrupt_->reason();
  return true;
}

bool Session::PassInterrupted(SolveSummary* summary) {
  if (!interrupt_->fired()) return false;
  summary->status = *interrupt_->reason();
  pass_interrupted_ = true;
  return true;
}

void Session::MakeInputsDiscrete(SolveSummary* summary) {
  const int N = problem_.horizon;
  double gap = 0.0;
  int rounded_steps = 0;
  if (options_.discrete_fixing_passes > 0 && algorithm_->algorithm() == Algorithm::kIake) {
    const int blocks = std::min(options_.discrete_fixing_blocks, N);
    bool stopped = false;
    for (int block = 0; block < blocks && !stopped; ++block) {
      const int end = static_cast<int>((static_cast<long long>(block) + 1) * N / blocks);
      for (; rounded_steps < end; ++rounded_steps) gap = std::max(gap, RoundDiscreteStep(rounded_steps, true));
      if (rounded_steps == N) break;  // nothing left to make up for the rounding
      for (int pass = 0; pass < options_.discrete_fixing_passes; ++pass) {
        if (StopNow(summary)) {
          stopped = true;
          break;
        }
        algorithm_->Iterate(&current_);
        if (PassInterrupted(summary)) {  // an incomplete pass: its plan is discarded
          stopped = true;
          break;
        }
        ++summary->iterations;
        if (!AllFinite(current_)) break;  // keep the last finite plan; its rounded part stays
        // The pinned inputs come back exactly as pinned; the rest is the re-solved plan.
        std::swap(best_, current_);
      }
    }
    algorithm_->ReleaseInputPins();
  }
  for (; rounded_steps < N; ++rounded_steps) gap = std::max(gap, RoundDiscreteStep(rounded_steps, false));
  const ObjectiveEvaluator::Result r = SearchDiscreteNeighbours(summary);
  summary->objective = r.objective;
  summary->max_violation = r.max_violation;
  summary->rounded = true;
  summary->discrete_gap = gap;
}

int Session::GroupEnd(int n, int first) const {
  int last = first;
  while (problem_.input_prior(n, last).rounds_with_next) ++last;
  return last;
}

bool Session::SameGroupAt(int n, int other, int first, int last) const {
  const ScalarPrior& here = problem_.input_prior(n, first);
  for (int j = first; j <= last; ++j) {
    const ScalarPrior& next = problem_.input_prior(other, j);
    if (next.kind != PriorKind::kBinary || next.lower != here.lower || next.upper != here.upper ||
        next.rounds_with_next != (j < last)) {
      return false;
    }
  }
  return true;
}

int Session::GroupLevel(int n, int first, int last) const {
  const ScalarPrior& prior = problem_.input_prior(n, first);
  int level = 0;
  for (int j = first; j <= last; ++j) level += best_.u(j, n) == prior.upper;
  return level;
}

void Session::SetGroupLevel(int n, int first, int last, int level) {
  const ScalarPrior& prior = problem_.input_prior(n, first);
  for (int j = first; j <= last; ++j) best_.u(j, n) = j - first < level ? prior.upper : prior.lower;
}

ObjectiveEvaluator::Result Session::SearchDiscreteNeighbours(SolveSummary* summary) {
  // The rounded plan's own evaluation is not interrupted: it is the one reported.
  ObjectiveEvaluator::Result current = evaluator_.Evaluate(problem_, best_);
  const double tolerance = options_.violation_tolerance * evaluator_.bound_scale();
  // Lower violation first (beyond the tolerance), then lower J.
  const auto better = [tolerance](const ObjectiveEvaluator::Result& trial, const ObjectiveEvaluator::Result& now) {
    if (!std::isfinite(trial.objective) || !std::isfinite(trial.max_violation)) return false;
    if (now.max_violation > tolerance || trial.max_violation > tolerance) {
      return trial.max_violation < now.max_violation - 0.5 * tolerance;
    }
    return trial.objective < now.objective - 1e-12 * (1.0 + std::abs(now.objective));
  };
  // An interrupted evaluation is NaN: never better, so the move is undone (and every
  // later one returns at once until the loops see the stop).
  const auto try_move = [&](auto&& apply, auto&& undo) {
    apply();
    const ObjectiveEvaluator::Result trial = evaluator_.Evaluate(problem_, best_, interrupt_);
    if (better(trial, current)) {
      current = trial;
      ++summary->discrete_moves;
      return true;
    }
    undo();
    return false;
  };
  const int N = problem_.horizon, L = problem_.num_inputs;
  for (int sweep = 0; sweep < options_.discrete_search_sweeps; ++sweep) {
    bool improved = false;
    for (int n = 0; n < N; ++n) {
      if (StopNow(summary)) return current;  // discrete, only less improved
      for (int first = 0; first < L; ++first) {
        if (problem_.input_prior(n, first).kind != PriorKind::kBinary) continue;
        const int last = GroupEnd(n, first);
        const int level = GroupLevel(n, first, last);
        for (const int step : {-1, 1}) {
          const int to = level + step;
          if (to < 0 || to > last - first + 1) continue;
          if (try_move([&] { SetGroupLevel(n, first, last, to); }, [&] { SetGroupLevel(n, first, last, level); })) {
            improved = true;
            break;
          }
        }
        // Move one level between this step and the next one's same group (same binaries):
        // a flap or a switch one step earlier or later, or a +1/-1 doublet, whose effect on
        // an integrator's output stays local.
        if (n + 1 < N && SameGroupAt(n, n + 1, first, last)) {
          const int here = GroupLevel(n, first, last), next = GroupLevel(n + 1, first, last);
          const int top = last - first + 1;
          const auto set_pair = [&](int a, int b) {
            SetGroupLevel(n, first, last, a);
            SetGroupLevel(n + 1, first, last, b);
          };
          for (const int step : {-1, 1}) {
            if (here + step < 0 || here + step > top || next - step < 0 || next - step > top) continue;
            if (try_move([&] { set_pair(here + step, next - step); }, [&] { set_pair(here, next); })) {
              improved = true;
              break;
            }
          }
        }
        first = last;
      }
    }
    if (!improved && options_.discrete_pair_reach > 0) improved = TryPairMove(summary, try_move);
    if (!improved) break;
  }
  return current;  // best_'s evaluation (Solve() re-evaluates it for the returned trajectories)
}

bool Session::MoveOneLevel(int n, int direction, int first, int last) {
  const int to = n + direction;
  if (to < 0 || to >= problem_.horizon || !SameGroupAt(n, to, first, last)) return false;
  const int here = GroupLevel(n, first, last), there = GroupLevel(to, first, last);
  if (here == 0 || there == last - first + 1) return false;
  SetGroupLevel(n, first, last, here - 1);
  SetGroupLevel(to, first, last, there + 1);
  return true;
}

template <typename TryMove>
bool Session::TryPairMove(SolveSummary* summary, TryMove& try_move) {
  const int N = problem_.horizon, L = problem_.num_inputs;
  for (int n1 = 0; n1 < N; ++n1) {
    if (StopNow(summary)) return false;
    for (int first = 0; first < L; ++first) {
      if (problem_.input_prior(n1, first).kind != PriorKind::kBinary) continue;
      const int last = GroupEnd(n1, first);
      if (GroupLevel(n1, first, last) > 0) {
        const int reach = std::min(N - 1, n1 + options_.discrete_pair_reach);
        for (int n2 = n1 + 1; n2 <= reach; ++n2) {
          if (!SameGroupAt(n1, n2, first, last) || GroupLevel(n2, first, last) == 0) continue;
          for (const int d1 : {-1, 1}) {
            for (const int d2 : {-1, 1}) {
              // Undone in reverse order, each move by its exact inverse.
              if (!MoveOneLevel(n1, d1, first, last)) continue;
              if (!MoveOneLevel(n2, d2, first, last)) {
                MoveOneLevel(n1 + d1, -d1, first, last);
                continue;
              }
              const auto undo = [&] {
                MoveOneLevel(n2 + d2, -d2, first, last);
                MoveOneLevel(n1 + d1, -d1, first, last);
              };
              if (try_move([] {}, undo)) return true;
            }
          }
        }
      }
      first = last;
    }
  }
  return false;
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
  const bool elastic_possible = elastic_applies_ && options_.elastic_after_iterations < max_iterations;
  SolveLimits hard_limits = limits;
  if (elastic_possible) hard_limits.max_iterations = options_.elastic_after_iterations;
  SolveSummary summary;
  if (PassInterrupted(&summary)) {
    summary.has_plan = false;
  } else {
    summary = RunLoop(hard_limits, warm);
    if (elastic_possible && summary.status == SolveStatus::kIterationLimit &&
        summary.max_violation > options_.violation_tolerance * evaluator_.bound_scale()) {
      ContinueElastic(limits, max_iterations, &summary);
    }
  }
  if (has_binary_inputs_ && summary.has_plan) MakeInputsDiscrete(&summary);
  // A limit reached anywhere (also inside an evaluation of the discrete search) is the status.
  if (interrupt.fired()) summary.status = *interrupt.reason();
  // A cancelled solve returns no plan, whatever it got to (the caller gave up on it).
  if (summary.status == SolveStatus::kCancelled) summary.has_plan = false;
  summary.solve_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  summary.warm_started = warm;
  summary.algorithm = algorithm_->algorithm();
  // The elastic fallback's carried state belongs to the elastic problem, not this one; an
  // interrupted pass may have left the carried state half updated.
  has_warm_state_ = summary.status != SolveStatus::kNumericalError && !summary.elastic && !pass_interrupted_;
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

void Session::ContinueElastic(const SolveLimits& limits, int max_iterations, SolveSummary* summary) {
  SolveLimits rest = limits;  // the time limit and cancel flag act through interrupt_
  rest.max_iterations = max_iterations - summary->iterations;
  if (StopNow(summary)) return;
  // The same algorithm on the elastic form (ElasticFormApplies checked it), from a cold
  // start: the hard problem's dual iterate may exceed the slope.
  SetBoundSlopes(hard_bounds_, options_.elastic_slope, &problem_);
  algorithm_->RefreshOutputPriors(problem_);
  algorithm_->ColdStart();
  evaluator_.Prepare(problem_);
  const SolveSummary elastic = RunLoop(rest, /*warm=*/false);
  // best_ is the elastic plan, or the hard loop's (a plan of this solve too).
  summary->has_plan = summary->has_plan || elastic.has_plan;
  SetBoundSlopes(hard_bounds_, kInfinity, &problem_);
  algorithm_->RefreshOutputPriors(problem_);
  evaluator_.Prepare(problem_);
  // best_ is the elastic plan (or, if the elastic loop broke down, the hard one): judged
  // against the hard bounds.
  const ObjectiveEvaluator::Result r = evaluator_.Evaluate(problem_, best_);
  summary->iterations += elastic.iterations;
  summary->objective = r.objective;
  summary->max_violation = r.max_violation;
  summary->polished = elastic.polished;
  summary->elastic = true;
  summary->status = elastic.status;
  if (elastic.status == SolveStatus::kConverged &&
      r.max_violation > options_.violation_tolerance * evaluator_.bound_scale()) {
    summary->status = SolveStatus::kInfeasible;
  }
}

SolveSummary Session::RunLoop(const SolveLimits& limits, bool warm) {
  const int max_iterations = IterationCap(limits);
  const double violation_tolerance = options_.violation_tolerance * evaluator_.bound_scale();
  const bool polish_enabled = options_.polish_after_stable_iterations > 0;

  SolveSummary summary;
  summary.status = SolveStatus::kIterationLimit;
  bool have_finite = false;  ///< best_ holds a complete, finite iterate of this loop

  const auto stop_requested = [&]() { return StopNow(&summary); };

  // Tries the active-set polish (1 + polish_rounds passes, more up to polish_max_rounds
  // while the deciding residual keeps falling); true if it was accepted.
  const auto try_polish = [&]() {
    double best_residual = kInfinity;
    for (int round = 0; summary.iterations < max_iterations; ++round) {
      if (round > 0 && stop_requested()) return false;  // up to 13 passes: honour the limits
      const double residual = algorithm_->Polish(&candidate_);
      if (PassInterrupted(&summary)) return false;  // an incomplete pass: discarded
      ++summary.iterations;
      const bool progress = residual < best_residual;
      best_residual = std::min(best_residual, residual);
      if (residual <= violation_tolerance && AllFinite(candidate_)) {
        const ObjectiveEvaluator::Result r = evaluator_.Evaluate(problem_, candidate_, interrupt_);
        if (interrupt_->fired()) return false;  // not evaluated: not accepted
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
        if (interrupt_->fired()) return false;
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
  const auto settled_changes = [&]() {
    return (algorithm_->NextPolishSolvesInputsOnly() ? options_.input_polish_settled_fraction
                                                     : options_.polish_settled_fraction) *
           algorithm_->decided_scalars();
  };
  while (summary.iterations < max_iterations) {
    if (stop_requested()) break;
    const int changed = algorithm_->Iterate(&current_);
    if (PassInterrupted(&summary)) break;  // an incomplete pass: discarded
    ++summary.iterations;
    const ObjectiveEvaluator::Result r =
        AllFinite(current_) ? evaluator_.Evaluate(problem_, current_, interrupt_) : ObjectiveEvaluator::Result{NAN, NAN};
    if (interrupt_->fired()) {  // a complete pass, not evaluated: not returned either
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
        !has_nonconvex_priors_ ||
        (current_.u - best_.u).cwiseAbs().maxCoeff() <= kNonconvexStepTolerance * (1.0 + current_.u.cwiseAbs().maxCoeff());
    std::swap(best_, current_);
    have_finite = true;
    summary.objective = r.objective;
    summary.max_violation = r.max_violation;
    const bool objective_settled =
        iterate_settled &&
        std::abs(r.objective - previous_objective) <= options_.objective_tolerance * std::abs(r.objective);
    if (objective_settled && r.max_violation <= violation_tolerance) {
      summary.status = SolveStatus::kConverged;
      break;
    }
    previous_objective = r.objective;

    stable = changed >= 0 && changed <= settled_changes() ? stable + 1 : 0;
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
