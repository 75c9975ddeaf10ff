#include "loadtest/step_as_server.h"

#include "server/step_conversion.h"

namespace nupmpc::loadtest {

absl::StatusOr<core::SolveSummary> StepAsTheServerDoes(core::MpcSession& session, const v1::Step& message,
                                                       bool warm_start, core::Solution* solution) {
  absl::StatusOr<core::StepUpdate> step = server::StepUpdateFromProto(message, session.dimensions());
  if (!step.ok()) return step.status();
  if (absl::Status applied = session.Apply(*step); !applied.ok()) return applied;
  session.ShiftWarmStart();
  core::SolveLimits limits;
  limits.warm_start = warm_start;
  return session.Solve(limits, solution);
}

}  // namespace nupmpc::loadtest
