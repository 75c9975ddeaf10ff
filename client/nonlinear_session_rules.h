#ifndef NUPMPC_CLIENT_NONLINEAR_SESSION_RULES_H_
#define NUPMPC_CLIENT_NONLINEAR_SESSION_RULES_H_

// What a NonlinearSession accepts before it sends anything: its options and the spec it
// fills in, checked against the model. Errors are INVALID_ARGUMENT naming the option
// (NonlinearSessionOptions....) or the spec's field (spec....).

#include "absl/status/status.h"
#include "client/nonlinear_model.h"
#include "client/nonlinear_session.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::nonlinear_internal {

absl::Status ValidateOptions(const NonlinearSessionOptions& options, const NonlinearModel& model);

// The spec's parts the session writes itself must be empty, and the rest must fit the model.
absl::Status ValidateSpec(const v1::ProblemSpec& spec, const NonlinearModel& model);

}  // namespace nupmpc::nonlinear_internal

#endif  // NUPMPC_CLIENT_NONLINEAR_SESSION_RULES_H_
