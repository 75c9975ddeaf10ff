#include "core/session/session.h"

#include <algorithm>
#include <chrono>
#include <limits>
#include <utility>

#include "core/algorithms/outer_iteration.h"
#include "core/algorithms/select.h"
#include "core/priors/scalar_rules.h"
#include "core/session/discrete_search.h"
#include "core/session/elastic.h"
#include "core/session/footprint.h"
#include "core/session/solve_loop.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

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
  return core::PassInterrupted(*interrupt_, summary, &pass_interrupted_);
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
  const SolveLoopParts parts{.problem = problem_,
                             .options = options_,
                             .algorithm = *algorithm_,
                             .evaluator = evaluator_,
                             .interrupt = *interrupt_,
                             .current = current_,
                             .candidate = candidate_,
                             .best = best_,
                             .least_violation = least_violation_,
                             .infeasibility = infeasibility_,
                             .pass_interrupted = pass_interrupted_,
                             .nonconvex_priors = has_nonconvex_priors_};
  return SolveLoop(parts, limits, IterationCap(limits)).Run(warm);
}

}  // namespace nupmpc::core
