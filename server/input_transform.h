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
  // The core's initial state for a measured x[0] (with differences: [x[0]; u[-1]]).
  Eigen::VectorXd CoreInitialState(const Eigen::VectorXd& measured) const;
  // The core's plan in the spec's terms (inputs u, the spec's outputs and states).
  void MapBack(core::Solution* solution) const;
  // After a solve: u[-1] of the next one is this plan's u[0] (differences only).
  void RememberApplied(const core::Solution& mapped);
};

// The problem the core solves for a spec whose base problem (ProblemFromSpec) is `base`,
// and the transform that maps it back. INVALID_ARGUMENT / FAILED_PRECONDITION naming the
// spec field.
absl::StatusOr<core::Problem> TransformProblem(const v1::ProblemSpec& spec, core::Problem base,
                                               InputTransform* transform);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_INPUT_TRANSFORM_H_
