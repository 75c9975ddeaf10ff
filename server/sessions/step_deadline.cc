#include "server/sessions/step_deadline.h"

#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"

namespace nupmpc::server {
namespace {

constexpr double kMaxPeriodMs = 3.6e6;  // an hour

std::chrono::nanoseconds Milliseconds(double ms) {
  return std::chrono::nanoseconds(static_cast<std::int64_t>(std::llround(ms * 1e6)));
}

void AnswerWithoutPlan(Clock::time_point due, v1::DeadlineOutcome outcome, v1::SolveResult* out) {
  out->Clear();
  out->set_status(v1::SOLVE_STATUS_TIME_LIMIT);
  out->set_has_plan(false);
  out->set_objective(std::numeric_limits<double>::quiet_NaN());
  out->set_max_violation(std::numeric_limits<double>::quiet_NaN());
  out->set_deadline(outcome);
  out->set_deadline_slack_ms(std::chrono::duration<double, std::milli>(due - Clock::now()).count());
}

}  // namespace

absl::StatusOr<SessionTiming> SessionTimingFromSpec(const v1::ProblemSpec& spec) {
  SessionTiming timing;
  timing.default_time_limit_ms = spec.options().time_limit_ms();
  const double period = spec.timing().period_ms();
  if (!(period >= 0.0) || !(period <= kMaxPeriodMs)) {
    return absl::InvalidArgumentError(
        absl::StrCat("spec.timing.period_ms = ", period, ": must be finite, >= 0 and at most ", kMaxPeriodMs));
  }
  timing.period_ms = period;
  timing.solve_late_steps = spec.timing().solve_late_steps();
  return timing;
}

std::optional<Clock::time_point> StepDue(const SessionTiming& timing, const v1::Step& step,
                                         Clock::time_point received_at) {
  const double budget_ms = step.budget_ms() > 0.0 ? step.budget_ms() : timing.period_ms;
  if (!(budget_ms > 0.0)) return std::nullopt;
  return received_at + Milliseconds(budget_ms);
}

void AnswerQueuedPastDeadline(Clock::time_point due, v1::SolveResult* out) {
  AnswerWithoutPlan(due, v1::DEADLINE_OUTCOME_QUEUED_PAST_DEADLINE, out);
}

void AnswerCannotFinishAPass(Clock::time_point due, v1::SolveResult* out) {
  AnswerWithoutPlan(due, v1::DEADLINE_OUTCOME_SOLVE_TOO_LONG, out);
}

void RecordDeadlineOutcome(std::optional<Clock::time_point> due, bool started_late, v1::SolveResult* out) {
  if (!due.has_value()) return;
  const double slack_ms = std::chrono::duration<double, std::milli>(*due - Clock::now()).count();
  out->set_deadline_slack_ms(slack_ms);
  if (started_late) {
    out->set_deadline(v1::DEADLINE_OUTCOME_QUEUED_PAST_DEADLINE);
  } else if (slack_ms < 0.0 || (!out->has_plan() && out->status() == v1::SOLVE_STATUS_TIME_LIMIT)) {
    out->set_deadline(v1::DEADLINE_OUTCOME_SOLVE_TOO_LONG);
  } else {
    out->set_deadline(v1::DEADLINE_OUTCOME_MET);
  }
}

}  // namespace nupmpc::server
