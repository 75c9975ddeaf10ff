#ifndef NUPMPC_SERVER_CONVERT_KEEP_OUT_CONVERSION_H_
#define NUPMPC_SERVER_CONVERT_KEEP_OUT_CONVERSION_H_

// ProblemSpec.keep_out → the core's keep-out regions and sequential-linearisation
// options. Every error names the proto field path ("spec.keep_out.regions[2].half_axis_b").

#include "absl/status/statusor.h"
#include "core/public/nonlinear.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {

// `num_outputs` is the spec's (the plane's coordinates must be two of them).
absl::StatusOr<core::KeepOut> KeepOutFromSpec(const v1::KeepOut& spec, int num_outputs);
absl::StatusOr<core::SequentialOptions> SequentialOptionsFromSpec(const v1::KeepOut& spec);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_CONVERT_KEEP_OUT_CONVERSION_H_
