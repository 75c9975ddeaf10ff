#ifndef NUPMPC_SERVER_CONVERT_SPEC_CONVERSION_H_
#define NUPMPC_SERVER_CONVERT_SPEC_CONVERSION_H_

// ProblemSpec → core conversion. Every spec a client sends passes through here before it
// reaches the core: every error names the proto field path (e.g. "spec.model.a[2]") and
// the rule.

#include "absl/status/statusor.h"
#include "core/nupmpc.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {

// Size limits a spec must respect (RESOURCE_EXHAUSTED when exceeded).
struct SizeLimits {
  int max_states = 1000;
  int max_inputs = 1000;
  int max_outputs = 1000;
  int max_horizon = 100000;
  // Largest number of doubles a session may hold in its model and priors (memory bound).
  long long max_scalars = 50'000'000;
  int max_iterations = 100000;
  // Training pairs of a GP model (memory O(P²), fit time O(P³) per iteration).
  int max_gp_points = 5000;
  // Levels of one multi-level input (each adds count - 1 binary inputs per step).
  int max_input_levels = 64;
  int max_keep_out_regions = 256;
  // What one session (or one-off solve, or fit) may cost, estimated from the spec before
  // anything is allocated (server/convert/session_cost.h).
  long long max_session_bytes = 2LL << 30;
  double max_pass_flops = 1e12;  ///< one message-passing pass over the horizon
};

// A v1::Matrix of the given size with finite entries; INVALID_ARGUMENT naming `path`.
absl::StatusOr<Eigen::MatrixXd> MatrixFromProto(const v1::Matrix& m, int rows, int cols, const std::string& path);

// RESOURCE_EXHAUSTED naming `field` when value > limit.
absl::Status CheckLimit(const char* field, long long value, long long limit);

// The problem of a spec, validated (INVALID_ARGUMENT naming the field, RESOURCE_EXHAUSTED
// for sizes over `limits`).
absl::StatusOr<core::Problem> ProblemFromSpec(const v1::ProblemSpec& spec, const SizeLimits& limits);

// One ComponentPrior's `steps` scalar priors, written to out[n * stride + offset];
// INVALID_ARGUMENT naming `path` and the field.
absl::Status ComponentPriorsFromProto(const v1::ComponentPrior& component, int steps, const std::string& path,
                                      std::vector<core::ScalarPrior>* out, int stride, int offset);

// The solver options of a spec (defaults where fields are 0).
absl::StatusOr<core::SolverOptions> OptionsFromSpec(const v1::SolverOptions& options, const SizeLimits& limits);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_CONVERT_SPEC_CONVERSION_H_
