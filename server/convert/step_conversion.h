#ifndef NUPMPC_SERVER_CONVERT_STEP_CONVERSION_H_
#define NUPMPC_SERVER_CONVERT_STEP_CONVERSION_H_

// A v1::Step as the core's StepUpdate: the one place where the service reads a Step.
// What is wrong whatever the session (an unknown warm_start, a negative time limit, a
// prior's values) is refused here, naming the step field; what depends on the session
// (sizes, indices, which fields its kind takes) is checked by the session's Apply, whose
// messages name the same fields without the "step." prefix.

#include "absl/status/statusor.h"
#include "core/nupmpc.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {

// The update of `step` for a session of `dimensions` (its horizon sizes the priors).
absl::StatusOr<core::StepUpdate> StepUpdateFromProto(const v1::Step& step, const core::Dimensions& dimensions);

// Step.warm_start applied to a session about to solve the step: SHIFT (and UNSPECIFIED)
// moves its warm start one step on, KEEP leaves it as it is, COLD solves without it
// (`limits`). An unknown value (StepUpdateFromProto refuses it) changes nothing.
void ApplyWarmStart(v1::WarmStart warm_start, core::MpcSession& session, core::SolveLimits* limits);

// A status of the session's Apply with its field names as the Step's ("step.state[0] ...";
// a message that names no field gets "step: ").
absl::Status AsStepError(const absl::Status& status);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_CONVERT_STEP_CONVERSION_H_
