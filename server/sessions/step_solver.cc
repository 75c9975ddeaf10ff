#include "server/sessions/step_solver.h"

#include <algorithm>
#include <optional>

#include "absl/strings/str_cat.h"
#include "core/public/status_macros.h"
#include "server/convert/result_conversion.h"
#include "server/convert/step_conversion.h"
#include "server/scheduling/thread_cpu_time.h"
#include "server/sessions/model_storage.h"
#include "server/sessions/session_factory.h"
#include "server/sessions/step_deadline.h"

namespace nupmpc::server {

namespace {

// Takes the budget's share the step needs (the scratch an idle session gave back, storage
// for a model that becomes per-step), then applies the update.
absl::Status ReserveAndApply(SessionEntry& entry, const core::StepUpdate& update) {
  if (entry.compacted) {
    // NOLINTNEXTLINE(performance-no-automatic-move): NUPMPC_RETURN_IF_ERROR's const local (core/util/status_macros.h)
    NUPMPC_RETURN_IF_ERROR(entry.memory.scratch.GrowTo(
        entry.memory.scratch_bytes, "session_id (allocating the idle session's solver scratch again)"));
  }
  // NOLINTNEXTLINE(performance-no-automatic-move): NUPMPC_RETURN_IF_ERROR's const local (core/util/status_macros.h)
  if (update.changes_model()) NUPMPC_RETURN_IF_ERROR(ReserveModelStorage(*entry.solver, update.model, &entry.memory));
  return AsStepError(entry.solver->Apply(update));
}

}  // namespace

absl::Status SolveStep(SessionEntry& entry, const v1::Step& step, const CallContext& call, v1::SolveResult* out) {
  if (entry.closed) return absl::NotFoundError(absl::StrCat("session_id \"", entry.id, "\": closed"));
  entry.Touch();
  core::MpcSession& solver = *entry.solver;
  NUPMPC_ASSIGN_OR_RETURN(const core::StepUpdate update, StepUpdateFromProto(step, solver.dimensions()));
  NUPMPC_ASSIGN_OR_RETURN(core::SolveLimits limits, SolveLimitsFor(entry.timing.default_time_limit_ms, &step, call));
  // A refused step leaves the session as it was, its share of the budget included (the
  // core checks an update when it applies it, after the storage for it was reserved).
  const std::int64_t resident_before = entry.memory.resident.bytes();
  const std::int64_t scratch_before = entry.memory.scratch.bytes();
  if (absl::Status applied = ReserveAndApply(entry, update); !applied.ok()) {
    entry.memory.resident.ShrinkTo(resident_before);
    entry.memory.scratch.ShrinkTo(scratch_before);
    return applied;
  }
  entry.algorithm.store(solver.algorithm());  // other priors may need another algorithm

  ApplyWarmStart(step.warm_start(), solver, &limits);
  // The step's deadline (step_deadline.h): the solve gets what is left of it, less the cost
  // of sending the answer and a margin of one pass. One that could not start in time, or whose
  // time left is shorter than the session's shortest pass, is answered at once without a plan
  // (its update applied above, as for any answered step) unless the session wants it
  // solved late.
  const std::optional<Clock::time_point> due =
      call.received_at.has_value() ? StepDue(entry.timing, step, *call.received_at) : std::nullopt;
  bool started_late = false;
  if (due.has_value()) {
    // What is left once the answer has been sent.
    const double left_s = std::chrono::duration<double>(*due - Clock::now()).count() - call.send_cost_ms * 1e-3;
    if (left_s <= 0.0 && !entry.timing.solve_late_steps) {
      AnswerQueuedPastDeadline(*due, out);
      entry.Touch();
      return absl::OkStatus();
    }
    started_late = left_s <= 0.0;
    const double pass_s = entry.last_pass_ms.load(std::memory_order_relaxed) * 1e-3;
    const double shortest_pass_s = entry.shortest_pass_ms.load(std::memory_order_relaxed) * 1e-3;
    const bool cannot_finish_a_pass = !started_late && left_s < shortest_pass_s;
    if (cannot_finish_a_pass && !entry.timing.solve_late_steps) {
      AnswerCannotFinishAPass(*due, out);
      entry.Touch();
      return absl::OkStatus();
    }
    // A session that wants late plans gets one here as for a step that started late: a
    // limit shorter than a pass would end the solve before its first.
    if (!started_late && !cannot_finish_a_pass) {
      // A pass cut by the limit is discarded, and a plan needs one whole pass: the limit
      // leaves the last pass's time as a margin, but never less than a pass (the time left
      // is at least the shortest).
      const double limit_s = std::max({left_s - pass_s, shortest_pass_s, 1e-6});
      limits.time_limit_seconds =
          limits.time_limit_seconds > 0.0 ? std::min(limits.time_limit_seconds, limit_s) : limit_s;
    }
  }
  // Read on every solve, short ones included, although the thread CPU clock is a system
  // call: the reading also brings the scheduler's account of this thread up to date, and
  // without it the tail latency at many streams on one core grew (server/README.md, "Where
  // a step is solved").
  const std::chrono::nanoseconds cpu_before = ThreadCpuTime();
  NUPMPC_ASSIGN_OR_RETURN(const core::SolveSummary summary, solver.Solve(limits, &entry.solution));
  entry.compacted = false;  // Solve() took its scratch back
  // Wall time for the pool's admission (a wait it promises in wall time), CPU time for where
  // the next step is solved: judged by wall time, a solve that shared its core with another
  // would look long and send its session's next steps to a worker.
  entry.last_solve_ms.store(summary.solve_seconds * 1e3, std::memory_order_relaxed);
  entry.last_solve_cpu_ms.store(std::chrono::duration<double, std::milli>(ThreadCpuTime() - cpu_before).count(),
                                std::memory_order_relaxed);
  entry.solves.fetch_add(1, std::memory_order_relaxed);
  if (summary.iterations > 0) {
    const double pass_ms = summary.solve_seconds * 1e3 / summary.iterations;
    entry.last_pass_ms.store(pass_ms, std::memory_order_relaxed);
    // One solve at a time per session: no other writer between the load and the store.
    const double shortest = entry.shortest_pass_ms.load(std::memory_order_relaxed);
    if (shortest == 0.0 || pass_ms < shortest) entry.shortest_pass_ms.store(pass_ms, std::memory_order_relaxed);
  }
  ResultToProto(summary, entry.solution, out);
  RecordDeadlineOutcome(due, started_late, out);
  entry.Touch();
  return absl::OkStatus();
}

absl::Status SolveOnce(const v1::ProblemSpec& spec, const SizeLimits& size_limits, const CallContext& call,
                       v1::SolveResult* out, GpModelCache* gp_models, MemoryBudget* budget) {
  NUPMPC_ASSIGN_OR_RETURN(BuiltSession built, BuildSession(spec, size_limits, gp_models, &call, budget));
  NUPMPC_ASSIGN_OR_RETURN(const core::SolveLimits limits,
                          SolveLimitsFor(built.timing.default_time_limit_ms, nullptr, call));
  core::Solution solution;
  NUPMPC_ASSIGN_OR_RETURN(const core::SolveSummary summary, built.solver->Solve(limits, &solution));
  ResultToProto(summary, solution, out);
  return absl::OkStatus();
}

}  // namespace nupmpc::server
