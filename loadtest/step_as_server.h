#ifndef NUPMPC_LOADTEST_STEP_AS_SERVER_H_
#define NUPMPC_LOADTEST_STEP_AS_SERVER_H_

// One Control step as nupmpc-server's SolveStep runs it, without the service around it:
// the Step message converted (the server's own StepUpdateFromProto), its limits (the
// session's time limit, the step's time_limit_ms and max_iterations), applied, the warm
// start shifted, kept or dropped as the step asks, the solve. What the core-alone
// baselines time and the bare peer answers.

#include "absl/status/statusor.h"
#include "core/nupmpc.h"
#include "nupmpc/v1/nupmpc.pb.h"
#include "server/sessions/session_factory.h"

namespace nupmpc::loadtest {

absl::StatusOr<core::SolveSummary> StepAsTheServerDoes(server::BuiltSession& session, const v1::Step& message,
                                                       core::Solution* solution);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_STEP_AS_SERVER_H_
