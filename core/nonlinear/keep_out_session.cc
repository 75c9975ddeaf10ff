#include "core/nonlinear/keep_out_session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

// Receding horizon: row n+1 becomes row n, the last row repeated. In place, no allocation.
void ShiftRowsUp(Eigen::MatrixXd* m) {
  const Eigen::Index rows = m->rows();
  if (rows < 2) return;
  for (Eigen::Index r = 0; r + 1 < rows; ++r) m->row(r) = m->row(r + 1);
}

// A matrix that is either empty (no plan yet) or rows × cols.
void PersistOptionalMatrix(StateArchive& archive, const char* present_name, const char* name, Eigen::MatrixXd& m,
                           Eigen::Index rows, Eigen::Index cols) {
  bool present = m.size() != 0;
  archive.Flag(present_name, present);
  if (!archive.ok()) return;
  if (archive.restoring()) {
    if (!present) {
      m.resize(0, 0);
      return;
    }
    if (!archive.Reserve(name, static_cast<std::size_t>(rows * cols) * sizeof(double))) return;
    m.setZero(rows, cols);
  }
  if (present) archive.Field(name, m);
}

}  // namespace

KeepOutSession::KeepOutSession(KeepOut keep_out, std::unique_ptr<SequentialSolver> solver,
                               std::unique_ptr<Session> free_planner, int max_iterations)
    : keep_out_(std::move(keep_out)),
      max_iterations_(max_iterations),
      solver_(std::move(solver)),
      free_planner_(std::move(free_planner)) {
  all_regions_hard_ = std::all_of(keep_out_.regions.begin(), keep_out_.regions.end(),
                                  [](const KeepOutRegion& region) { return std::isinf(region.slope); });
  free_planner_->ReleaseWorkspace();
}

absl::StatusOr<std::unique_ptr<KeepOutSession>> KeepOutSession::Create(Problem plant, KeepOut keep_out,
                                                                       SolverOptions solver_options,
                                                                       SequentialOptions options) {
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<Linearisation> linearisation, MakeKeepOutLinearisation(plant, keep_out));
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<SequentialSolver> solver,
                          SequentialSolver::Create(std::move(linearisation), solver_options, options));
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<Session> free_planner, Session::Create(std::move(plant), solver_options));
  return std::unique_ptr<KeepOutSession>(new KeepOutSession(std::move(keep_out), std::move(solver),
                                                            std::move(free_planner), solver_options.max_iterations));
}

absl::StatusOr<bool> KeepOutSession::PlanWithoutRegions(const SolveLimits& limits, SolveSummary* stopped) {
  SolveLimits cold = limits;
  cold.warm_start = false;
  NUPMPC_ASSIGN_OR_RETURN(const SolveSummary summary, free_planner_->Solve(cold, &guess_));
  free_planner_->ReleaseWorkspace();
  if (!summary.has_plan) {
    if (summary.status == SolveStatus::kTimeLimit || summary.status == SolveStatus::kCancelled) {
      // Stopped before a first plan: not the problem's fault, and nothing to return.
      *stopped = summary;
      return false;
    }
    // Without regions the plant's problem is convex; failing it is the problem's fault.
    return absl::InvalidArgumentError(
        absl::StrCat("the problem without keep-out regions has no usable plan: ", summary.Describe()));
  }
  return true;
}

absl::Status KeepOutSession::SetInitialState(const Eigen::VectorXd& x0) {
  // Both run CheckInitialState: once the first accepts x0, the planner accepts it too.
  NUPMPC_RETURN_IF_ERROR(solver_->SetInitialState(x0));
  return free_planner_->SetInitialState(x0);
}

absl::Status KeepOutSession::Update(const Problem& plant) {
  NUPMPC_RETURN_IF_ERROR(solver_->SetBase(plant));  // validates first; unchanged on error
  // Same shape and valid: only an algorithm that cannot be built could refuse it now.
  NUPMPC_RETURN_IF_ERROR(free_planner_->Update(plant));
  free_planner_->ReleaseWorkspace();
  return absl::OkStatus();
}

absl::Status KeepOutSession::Apply(const StepUpdate& update) {
  if (update.changes_model()) {
    // The linearisation's problem has the plant's storage of A and B: it cannot follow a
    // change of it (checked before the planner changes anything).
    NUPMPC_RETURN_IF_ERROR(CheckModelChanges(free_planner_->problem(), update.model));
    if (ModelChangesStorage(free_planner_->problem(), update.model)) {
      return absl::FailedPreconditionError(
          "model: a keep-out session takes per-step model entries only for the matrices it stores per step; create "
          "it with N matrices A and B (N + 1 for C) to update them step by step");
    }
  }
  NUPMPC_RETURN_IF_ERROR(free_planner_->Apply(update));  // checks everything; unchanged on error
  if (update.changes_priors() || update.changes_model()) {
    // Same shape and valid (the planner accepted it): the linearisation cannot refuse it.
    NUPMPC_RETURN_IF_ERROR(solver_->SetBase(free_planner_->problem()));
    free_planner_->ReleaseWorkspace();
  } else if (update.state.has_value()) {
    NUPMPC_RETURN_IF_ERROR(solver_->SetInitialState(*update.state));
  }
  return absl::OkStatus();
}

void KeepOutSession::ShiftWarmStart() {
  solver_->ShiftWarmStart();
  ShiftRowsUp(&guess_.states);
  ShiftRowsUp(&guess_.inputs);
}

absl::StatusOr<SolveSummary> KeepOutSession::Solve(const SolveLimits& limits, Solution* solution) {
  const auto start = std::chrono::steady_clock::now();
  const bool warm = limits.warm_start && has_plan_;
  if (!warm) {
    SolveSummary stopped;
    NUPMPC_ASSIGN_OR_RETURN(const bool planned, PlanWithoutRegions(limits, &stopped));
    if (!planned) {
      stopped.has_plan = false;
      stopped.warm_started = false;
      if (solution != nullptr) *solution = Solution{};
      return stopped;
    }
  }
  // The plan starts at the measured state whatever the previous plan predicted.
  guess_.states.row(0) = problem().initial_mean.transpose();
  SolveLimits capped = limits;
  if (capped.max_iterations == 0) capped.max_iterations = max_iterations_;
  if (limits.time_limit_seconds > 0.0) {
    // One time limit for the whole solve: the cold start's plan took part of it.
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    capped.time_limit_seconds = limits.time_limit_seconds - elapsed;
    if (capped.time_limit_seconds <= 0.0) {
      SolveSummary stopped;
      stopped.status = SolveStatus::kTimeLimit;
      stopped.algorithm = algorithm();
      stopped.has_plan = false;
      stopped.objective = stopped.max_violation = std::numeric_limits<double>::quiet_NaN();
      stopped.solve_seconds = elapsed;
      if (solution != nullptr) *solution = Solution{};
      return stopped;
    }
  }
  NUPMPC_ASSIGN_OR_RETURN(const SequentialSummary sequence, solver_->Solve(guess_, &plan_, capped));

  SolveSummary summary = sequence.last_inner;
  summary.iterations = sequence.inner_iterations;
  summary.linearisations = sequence.linearisations;
  summary.nonlinear_violation = sequence.nonlinear_violation;
  summary.solve_seconds = sequence.solve_seconds;
  summary.warm_started = warm;
  if (all_regions_hard_) summary.max_violation = std::max(summary.max_violation, sequence.nonlinear_violation);
  if (!sequence.converged && summary.status == SolveStatus::kConverged) summary.status = SolveStatus::kIterationLimit;

  // A plan of this solve for this x[0]: some linearised problem produced one (the last
  // inner solve may have been stopped before its first pass), and the solve was not cancelled.
  summary.has_plan = sequence.has_plan && summary.status != SolveStatus::kCancelled;
  if (!summary.has_plan) {
    summary.objective = summary.max_violation = std::numeric_limits<double>::quiet_NaN();
    if (!sequence.has_plan) summary.nonlinear_violation = std::numeric_limits<double>::quiet_NaN();
  }
  if (sequence.has_plan) {
    // The next linearisation point (also after a cancel: it is a plan for this state).
    guess_.states = plan_.states;
    guess_.inputs = plan_.inputs;
    has_plan_ = true;
  }
  if (solution != nullptr) {
    if (summary.has_plan) {
      solution->inputs = plan_.inputs;
      solution->states = plan_.states;
      solution->outputs = plan_.outputs.leftCols(problem().num_outputs);
    } else {
      *solution = Solution{};
    }
  }
  return summary;
}

absl::Status KeepOutSession::SaveState(std::string* out) {
  std::string planner, linearised;
  NUPMPC_RETURN_IF_ERROR(free_planner_->SaveState(&planner));
  NUPMPC_RETURN_IF_ERROR(solver_->SaveState(&linearised));
  StateWriter writer(out);
  PersistState(writer, planner, linearised);
  return writer.status();
}

absl::Status KeepOutSession::RestoreState(std::string_view bytes) {
  std::string planner, linearised;
  StateReader reader(bytes);
  PersistState(reader, planner, linearised);
  NUPMPC_RETURN_IF_ERROR(reader.status());
  const auto named = [](const char* part, const absl::Status& status) {
    return status.code() == absl::StatusCode::kInvalidArgument
               ? absl::InvalidArgumentError(absl::StrCat("keep_out.", part, ": ", status.message()))
               : status;
  };
  // The plant's values first (validated as an update's), then the linearisation's base
  // from them, as Apply() does, with the current x[0] (which Apply() sets alone).
  if (absl::Status s = free_planner_->RestoreState(planner); !s.ok()) return named("free_planner", s);
  NUPMPC_RETURN_IF_ERROR(solver_->SetBase(free_planner_->problem()));
  NUPMPC_RETURN_IF_ERROR(solver_->SetInitialState(free_planner_->problem().initial_mean));
  if (absl::Status s = solver_->RestoreState(linearised); !s.ok()) return named("linearised", s);
  return absl::OkStatus();
}

void KeepOutSession::PersistState(StateArchive& archive, std::string& planner, std::string& linearised) {
  archive.BeginSection("keep_out");
  // Bounded by the input itself (the reader checks what is left before copying).
  archive.Blob("free_planner", planner, std::numeric_limits<std::size_t>::max());
  archive.Blob("linearised", linearised, std::numeric_limits<std::size_t>::max());
  archive.Flag("has_plan", has_plan_);
  // The linearisation point (its outputs are recomputed by every linearisation).
  const Problem& p = free_planner_->problem();
  PersistOptionalMatrix(archive, "has_guess_states", "guess_states", guess_.states, p.horizon + 1, p.num_states);
  PersistOptionalMatrix(archive, "has_guess_inputs", "guess_inputs", guess_.inputs, p.horizon, p.num_inputs);
  archive.EndSection();
}

}  // namespace nupmpc::core
