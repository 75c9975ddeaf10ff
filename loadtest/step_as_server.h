#ifndef NUPMPC_LOADTEST_STEP_AS_SERVER_H_
#define NUPMPC_LOADTEST_STEP_AS_SERVER_H_

// One Control step as nupmpc-server's SolveStep runs it, without the service around it:
// the Step message converted (the server's own StepUpdateFromProto), applied, the warm
// start shifted, the solve. What the core-alone baselines time and the bare peer answers.

#include "absl/status/statusor.h"
#include "core/session/mpc_session.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::loadtest {

absl::StatusOr<core::SolveSummary> StepAsTheServerDoes(core::MpcSession& session, const v1::Step& message,
                                                       bool warm_start, core::Solution* solution);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_STEP_AS_SERVER_H_
