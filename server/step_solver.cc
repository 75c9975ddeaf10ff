#include "server/step_solver.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/gp/gp_mpc_session.h"
#include "core/nonlinear/keep_out_session.h"
#include "core/util/status_macros.h"
#include "server/gp_conversion.h"
#include "server/keep_out_conversion.h"
#include "server/session_cost.h"

namespace nupmpc::server {
namespace {

// Combines the session's, the step's and the deadline's time limits (0 = none).
absl::Status MakeLimits(double session_limit_ms, const v1::Step* step, const CallContext& call,
                        core::SolveLimits* limits) {
  double limit_ms = session_limit_ms;
  if (step != nullptr && step->time_limit_ms() > 0.0) {
    limit_ms = limit_ms > 0.0 ? std::min(limit_ms, step->time_limit_ms()) : step->time_limit_ms();
  }
  if (call.deadline.has_value()) {
    const double left_ms = std::chrono::duration<double, std::milli>(*call.deadline - Clock::now()).count();
    if (left_ms <= 0.0) return absl::DeadlineExceededError("the deadline passed before the solve started");
    limit_ms = limit_ms > 0.0 ? std::min(limit_ms, left_ms) : left_ms;
  }
  limits->time_limit_seconds = limit_ms > 0.0 ? limit_ms * 1e-3 : 0.0;
  limits->cancel = call.cancel;
  if (step != nullptr) limits->max_iterations = static_cast<int>(step->max_iterations());
  return absl::OkStatus();
}

// A step's previous_input (only for Δu sessions), else the session's; nothing written on error.
absl::Status ReadPreviousInput(const v1::Step& step, const InputTransform& transform, Eigen::VectorXd* out) {
  if (step.previous_input_size() == 0) {
    if (transform.differences) *out = transform.previous_input;
    return absl::OkStatus();
  }
  if (!transform.differences) {
    return absl::InvalidArgumentError("step.previous_input: only for sessions with input_differences");
  }
  return ReadInputVector(step.previous_input(), transform.num_inputs, "step.previous_input",
                          absl::StatusCode::kFailedPrecondition, out);
}

// A GP session's step: the reference is the session's output means at steps 1..H (see
// GpMpcSession), replaced as a whole; checked completely before the session changes.
absl::Status ApplyGpStep(const v1::Step& step, const Eigen::VectorXd* measured, core::MpcSession& solver) {
  if (step.has_update()) {
    return absl::FailedPreconditionError("step.update: GP sessions take a new reference in step.reference");
  }
  if (step.reference_size() == 0) {
    return measured != nullptr ? solver.SetInitialState(*measured) : absl::OkStatus();
  }
  core::Problem candidate = solver.problem();
  const int H = candidate.horizon;
  if (step.reference_size() != 1 && step.reference_size() != H) {
    return absl::InvalidArgumentError(
        absl::StrCat("step.reference: expected 1 or ", H, " values (the horizon), got ", step.reference_size()));
  }
  for (int n = 0; n < H; ++n) {
    const double r = step.reference(step.reference_size() == 1 ? 0 : n);
    if (!std::isfinite(r)) {
      return absl::InvalidArgumentError(absl::StrCat("step.reference[", n, "] = ", r, ": must be finite"));
    }
    candidate.mutable_output_prior(n + 1, 0).mean = r;
  }
  if (measured != nullptr) candidate.initial_mean = *measured;
  return solver.Update(candidate);
}

}  // namespace

absl::StatusOr<gp::FitOptions> FitLimits(const CallContext* call) {
  gp::FitOptions fit;
  if (call == nullptr) return fit;
  fit.cancel = call->cancel;
  if (call->deadline.has_value()) {
    fit.max_seconds = std::chrono::duration<double>(*call->deadline - Clock::now()).count();
    if (fit.max_seconds <= 0.0) return absl::DeadlineExceededError("the deadline passed before the fit started");
  }
  return fit;
}

absl::Status CheckCallStillWanted(const CallContext& call, const char* what) {
  if (call.cancel != nullptr && call.cancel->load()) {
    return absl::CancelledError(absl::StrCat(what, " after the client cancelled the call; it was not kept"));
  }
  if (call.deadline.has_value() && Clock::now() > *call.deadline) {
    return absl::DeadlineExceededError(absl::StrCat(what, " after the call's deadline; it was not kept"));
  }
  return absl::OkStatus();
}

namespace {

// The solver of a spec (no admission: BuildSession does that first).
absl::Status BuildSolver(const v1::ProblemSpec& spec, const SizeLimits& limits, GpModelCache* gp_models,
                         const CallContext* call, BuiltSession* built);

}  // namespace

absl::StatusOr<BuiltSession> BuildSession(const v1::ProblemSpec& spec, const SizeLimits& limits,
                                          GpModelCache* gp_models, const CallContext* call, MemoryBudget* budget) {
  NUPMPC_ASSIGN_OR_RETURN(const SessionCost cost, SpecCost(spec, limits));
  MemoryBudget::Reservation reserved;
  if (budget != nullptr) {
    NUPMPC_ASSIGN_OR_RETURN(reserved, budget->Reserve(std::max(cost.build_bytes, cost.session_bytes()),
                                                      "spec (the session's problem, solver scratch and GP factors)"));
  }
  BuiltSession built;
  NUPMPC_RETURN_IF_ERROR(BuildSolver(spec, limits, gp_models, call, &built));
  reserved.ShrinkTo(cost.session_bytes());
  built.memory.scratch = reserved.Split(cost.scratch_bytes);
  built.memory.scratch_bytes = built.memory.scratch.bytes();
  built.memory.resident = std::move(reserved);
  return built;
}

absl::StatusOr<std::shared_ptr<SessionEntry>> CreateAndRegister(const v1::ProblemSpec& spec, const SizeLimits& limits,
                                                                GpModelCache* gp_models, MemoryBudget* budget,
                                                                SessionRegistry* registry, const CallContext& call,
                                                                bool owned_by_stream) {
  NUPMPC_ASSIGN_OR_RETURN(BuiltSession built, BuildSession(spec, limits, gp_models, &call, budget));
  NUPMPC_RETURN_IF_ERROR(CheckCallStillWanted(call, "the session was built"));
  return registry->Add(std::move(built.solver), built.default_time_limit_ms, owned_by_stream,
                       std::move(built.transform), std::move(built.memory));
}

namespace {

absl::Status BuildSolver(const v1::ProblemSpec& spec, const SizeLimits& limits, GpModelCache* gp_models,
                         const CallContext* call, BuiltSession* out) {
  BuiltSession& built = *out;
  if (spec.has_gp()) {
    NUPMPC_ASSIGN_OR_RETURN(const gp::FitOptions fit, FitLimits(call));
    NUPMPC_ASSIGN_OR_RETURN(built.solver, GpSessionFromSpec(spec, limits, gp_models, fit));
    built.default_time_limit_ms = spec.options().time_limit_ms();
    return absl::OkStatus();
  }
  NUPMPC_ASSIGN_OR_RETURN(core::Problem base, ProblemFromSpec(spec, limits));
  NUPMPC_ASSIGN_OR_RETURN(core::Problem problem, TransformProblem(spec, std::move(base), &built.transform));
  NUPMPC_ASSIGN_OR_RETURN(const core::SolverOptions options, OptionsFromSpec(spec.options(), limits));
  absl::StatusOr<std::unique_ptr<core::MpcSession>> solver;
  if (spec.has_keep_out()) {
    NUPMPC_ASSIGN_OR_RETURN(core::KeepOut keep_out,
                            KeepOutFromSpec(spec.keep_out(), static_cast<int>(spec.model().num_outputs())));
    NUPMPC_ASSIGN_OR_RETURN(const core::SequentialOptions sequential, SequentialOptionsFromSpec(spec.keep_out()));
    solver = core::KeepOutSession::Create(std::move(problem), std::move(keep_out), options, sequential);
  } else {
    solver = core::Session::Create(std::move(problem), options);
  }
  if (!solver.ok()) {
    // e.g. a forced algorithm that cannot handle the priors: the spec's fault.
    return absl::Status(solver.status().code(), absl::StrCat("spec: ", solver.status().message()));
  }
  built.solver = *std::move(solver);
  built.default_time_limit_ms = spec.options().time_limit_ms();
  return absl::OkStatus();
}

}  // namespace

absl::Status SolveStep(SessionEntry& entry, const v1::Step& step, const CallContext& call, v1::SolveResult* out) {
  std::lock_guard<std::mutex> lock(entry.mu);
  if (entry.closed) return absl::NotFoundError(absl::StrCat("session_id \"", entry.id, "\": closed"));
  entry.Touch();
  core::SolveLimits limits;
  NUPMPC_RETURN_IF_ERROR(MakeLimits(entry.default_time_limit_ms, &step, call, &limits));
  if (step.max_iterations() > static_cast<unsigned>(std::numeric_limits<int>::max())) {
    return absl::InvalidArgumentError("step.max_iterations: too large");
  }

  if (entry.compacted) {
    // Its scratch was given back while idle: take the budget's share again first.
    NUPMPC_RETURN_IF_ERROR(entry.memory.scratch.GrowTo(entry.memory.scratch_bytes,
                                                       "session_id (allocating the idle session's solver scratch again)"));
  }
  core::MpcSession& solver = *entry.solver;
  InputTransform& transform = entry.transform;
  // Everything but the update is checked before anything changes.
  NUPMPC_RETURN_IF_ERROR(ReadStepState(step, "step", entry.dims.num_states(), &entry.x0));
  Eigen::VectorXd previous_input;  // u[-1] of this solve (Δu sessions only)
  NUPMPC_RETURN_IF_ERROR(ReadPreviousInput(step, transform, &previous_input));
  const Eigen::VectorXd* measured = step.state_size() > 0 ? &entry.x0 : nullptr;
  const bool gp_session = dynamic_cast<const gp::GpMpcSession*>(&solver) != nullptr;
  if (!gp_session && step.reference_size() > 0) {
    return absl::InvalidArgumentError("step.reference: only for GP sessions (ProblemSpec.gp); use step.update");
  }
  if (gp_session) {
    NUPMPC_RETURN_IF_ERROR(ApplyGpStep(step, measured, solver));
  } else if (step.has_update()) {
    // References or bounds change: validate on a copy; Update() keeps the session as it
    // was if it rejects the problem.
    if (transform.active() && step.update().inputs_size() > 0) {
      return absl::FailedPreconditionError(
          "step.update.inputs: this session's inputs are multi-level or carry input-difference priors; "
          "their priors are fixed at creation");
    }
    core::Problem candidate = solver.problem();
    NUPMPC_RETURN_IF_ERROR(ApplyPriorUpdate(step.update(), "step.update", &candidate));
    if (transform.differences) {
      transform.WriteCoreInitialState(measured, previous_input, &candidate.initial_mean);
    } else if (measured != nullptr) {
      candidate.initial_mean = *measured;
    }
    NUPMPC_RETURN_IF_ERROR(solver.Update(candidate));
    entry.algorithm.store(solver.algorithm());
  } else if (transform.differences) {
    Eigen::VectorXd x = solver.problem().initial_mean;  // u[-1] changes every step
    transform.WriteCoreInitialState(measured, previous_input, &x);
    NUPMPC_RETURN_IF_ERROR(solver.SetInitialState(x));
  } else if (measured != nullptr) {
    // The common path: only the measured state changes (no copy of the problem).
    // ReadStepState checked size and finiteness, which is all SetInitialState checks.
    NUPMPC_RETURN_IF_ERROR(solver.SetInitialState(*measured));
  }

  switch (step.warm_start()) {
    case v1::WARM_START_UNSPECIFIED:
    case v1::WARM_START_SHIFT: solver.ShiftWarmStart(); break;
    case v1::WARM_START_KEEP: break;
    case v1::WARM_START_COLD: limits.warm_start = false; break;
    default: break;
  }
  NUPMPC_ASSIGN_OR_RETURN(const core::SolveSummary summary, solver.Solve(limits, &entry.solution));
  entry.compacted = false;  // Solve() took its scratch back
  entry.last_solve_ms.store(summary.solve_seconds * 1e3, std::memory_order_relaxed);
  entry.solves.fetch_add(1, std::memory_order_relaxed);
  if (transform.active() && summary.has_plan) {
    transform.MapBack(previous_input, &entry.solution);
    transform.RememberApplied(entry.solution);
  }
  ResultToProto(summary, entry.solution, out);
  entry.Touch();
  return absl::OkStatus();
}

absl::Status SolveOnce(const v1::ProblemSpec& spec, const SizeLimits& size_limits, const CallContext& call,
                       v1::SolveResult* out, GpModelCache* gp_models, MemoryBudget* budget) {
  NUPMPC_ASSIGN_OR_RETURN(BuiltSession built, BuildSession(spec, size_limits, gp_models, &call, budget));
  core::SolveLimits limits;
  NUPMPC_RETURN_IF_ERROR(MakeLimits(built.default_time_limit_ms, nullptr, call, &limits));
  core::Solution solution;
  NUPMPC_ASSIGN_OR_RETURN(const core::SolveSummary summary, built.solver->Solve(limits, &solution));
  if (summary.has_plan) built.transform.MapBack(built.transform.previous_input, &solution);
  ResultToProto(summary, solution, out);
  return absl::OkStatus();
}

}  // namespace nupmpc::server
