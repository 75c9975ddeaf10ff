#ifndef NUPMPC_SERVER_INPUT_TRANSFORM_H_
#define NUPMPC_SERVER_INPUT_TRANSFORM_H_

// The spec's multi-level inputs and input-difference priors (ProblemSpec.input_levels,
// .input_differences): the core solves an expanded or augmented problem; clients keep
// seeing their own inputs, outputs and states. This is the one place that maps between
// the two.

#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/model/multilevel_inputs.h"
#include "core/problem.h"
#include "core/solution.h"
#include "nupmpc/v1/nupmpc.pb.h"
#include "server/spec_conversion.h"

namespace nupmpc::server {

struct InputTransform {
  int num_states = 0, num_inputs = 0, num_outputs = 0;  ///< the spec's own dimensions
  std::vector<core::InputLevels> levels;                 ///< one per input; empty: none
  bool differences = false;
  Eigen::VectorXd previous_input;  ///< u[-1] of the next solve (differences only)

  bool active() const { return differences || !levels.empty(); }
  // Δu only: the core's x[0], [x[0]; u[-1]], from the core's current one with the
  // measured state (if any) and the u[-1] of this solve written in.
  void WriteCoreInitialState(const Eigen::VectorXd* measured, const Eigen::VectorXd& previous_input,
                             Eigen::VectorXd* core_x0) const;
  // The core's plan in the spec's terms (inputs u, the spec's outputs and states);
  // `previous_input` is the u[-1] the plan's differences start from (Δu only).
  void MapBack(const Eigen::VectorXd& previous_input, core::Solution* solution) const;
  // After a solve: u[-1] of the next one is this plan's u[0] (differences only).
  void RememberApplied(const core::Solution& mapped);
};

// `values` as a vector of `size` (= num_inputs) finite numbers; `size_error` is the code for a wrong
// count (INVALID_ARGUMENT in a spec, FAILED_PRECONDITION for a session's step).
absl::Status ReadInputVector(const google::protobuf::RepeatedField<double>& values, int size, const std::string& field,
                              absl::StatusCode size_error, Eigen::VectorXd* out);

// The problem the core solves for a spec whose base problem (ProblemFromSpec) is `base`,
// and the transform that maps it back. INVALID_ARGUMENT / FAILED_PRECONDITION naming the
// spec field.
absl::StatusOr<core::Problem> TransformProblem(const v1::ProblemSpec& spec, core::Problem base,
                                               InputTransform* transform);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_INPUT_TRANSFORM_H_
