#include "loadtest/step_as_server.h"

#include "server/convert/step_conversion.h"
#include "server/sessions/call_context.h"

namespace nupmpc::loadtest {

absl::StatusOr<core::SolveSummary> StepAsTheServerDoes(server::BuiltSession& session, const v1::Step& message,
                                                       core::Solution* solution) {
  core::MpcSession& solver = *session.solver;
  absl::StatusOr<core::StepUpdate> step = server::StepUpdateFromProto(message, solver.dimensions());
  if (!step.ok()) return step.status();
  absl::StatusOr<core::SolveLimits> limits =
      server::SolveLimitsFor(session.timing.default_time_limit_ms, &message, server::CallContext{});
  if (!limits.ok()) return limits.status();
  if (absl::Status applied = server::AsStepError(solver.Apply(*step)); !applied.ok()) return applied;
  switch (message.warm_start()) {
    case v1::WARM_START_KEEP:
      break;
    case v1::WARM_START_COLD:
      limits->warm_start = false;
      break;
    default:
      solver.ShiftWarmStart();
      break;
  }
  return solver.Solve(*limits, solution);
}

}  // namespace nupmpc::loadtest
