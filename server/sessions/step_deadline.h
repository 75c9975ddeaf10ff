#ifndef NUPMPC_SERVER_SESSIONS_STEP_DEADLINE_H_
#define NUPMPC_SERVER_SESSIONS_STEP_DEADLINE_H_

// When a step's answer is due and whether it made it (proto Timing, Step.budget_ms,
// SolveResult.deadline): one rule for every path a step takes (Control, Solve, SolveFleet),
// used both to order the waiting work (earliest deadline first) and to limit the solve.

#include <chrono>
#include <optional>

#include "absl/status/statusor.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {

using Clock = std::chrono::steady_clock;

// A session's deadlines, from its spec (ProblemSpec.timing, options.time_limit_ms).
struct SessionTiming {
  double default_time_limit_ms = 0.0;  ///< options.time_limit_ms: every solve's own limit
  double period_ms = 0.0;              ///< timing.period_ms; 0: steps without a budget have no deadline
  bool solve_late_steps = false;       ///< timing.solve_late_steps
};

// INVALID_ARGUMENT naming the field for a period that is negative, not finite or over an
// hour (a control period, not a timeout).
absl::StatusOr<SessionTiming> SessionTimingFromSpec(const v1::ProblemSpec& spec);

// When the answer to `step`, received at `received_at`, is due: its budget_ms, else the
// session's period; none without either.
std::optional<Clock::time_point> StepDue(const SessionTiming& timing, const v1::Step& step,
                                         Clock::time_point received_at);

// A step that could not start before its deadline, answered without a plan instead of
// being solved late: TIME_LIMIT, no plan, QUEUED_PAST_DEADLINE.
void AnswerQueuedPastDeadline(Clock::time_point due, v1::SolveResult* out);

// A step left less time than one pass of its session's solver takes: no plan could be
// ready by its deadline, so it is answered at once (TIME_LIMIT, no plan, SOLVE_TOO_LONG)
// instead of spending a pass that would end late anyway, time the steps behind it need.
void AnswerCannotFinishAPass(Clock::time_point due, v1::SolveResult* out);

// Sets out->deadline and deadline_slack_ms for an answer handed over now (nothing without
// a deadline). `started_late`: the solve began after the deadline (solve_late_steps).
void RecordDeadlineOutcome(std::optional<Clock::time_point> due, bool started_late, v1::SolveResult* out);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SESSIONS_STEP_DEADLINE_H_
