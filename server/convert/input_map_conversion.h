#ifndef NUPMPC_SERVER_CONVERT_INPUT_MAP_CONVERSION_H_
#define NUPMPC_SERVER_CONVERT_INPUT_MAP_CONVERSION_H_

// The spec's multi-level inputs and input-difference priors (ProblemSpec.input_levels,
// .input_differences) as the core's InputMap (core/session/input_mapped_session.h), which
// solves the expanded or augmented problem while clients keep seeing their own inputs.

#include "absl/status/statusor.h"
#include "core/nupmpc.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {

// The map of a spec whose base problem (ProblemFromSpec) is `base`. INVALID_ARGUMENT
// naming the spec field.
absl::StatusOr<core::InputMap> InputMapFromSpec(const v1::ProblemSpec& spec, const core::Problem& base);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_CONVERT_INPUT_MAP_CONVERSION_H_
