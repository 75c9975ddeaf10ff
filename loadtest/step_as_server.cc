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
  server::ApplyWarmStart(message.warm_start(), solver, &*limits);
  return solver.Solve(*limits, solution);
}

}  // namespace nupmpc::loadtest
