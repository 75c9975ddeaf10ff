#ifndef NUPMPC_CORE_SESSION_FOOTPRINT_H_
#define NUPMPC_CORE_SESSION_FOOTPRINT_H_

#include <cstdint>

namespace nupmpc::core {

// The shape of a problem, known before anything is allocated (a service reads it off the
// request to admit or refuse it).
struct ProblemShape {
  std::int64_t num_states = 0;   ///< M
  std::int64_t num_inputs = 0;   ///< L (after any expansion, e.g. binaries of M-level inputs)
  std::int64_t num_outputs = 0;  ///< K
  std::int64_t horizon = 0;      ///< N
  bool a_per_step = false;       ///< N matrices A (else one)
  bool b_per_step = false;
  bool c_per_step = false;
  bool uncertain_initial_state = false;  ///< an M×M initial covariance
  bool terminal_cost = false;            ///< an M×M terminal weight
};

// What a Session of that shape costs, as upper bounds for whichever algorithm it selects.
struct Footprint {
  std::int64_t problem_bytes = 0;    ///< the Problem: model matrices, priors
  std::int64_t workspace_bytes = 0;  ///< message-passing scratch (released while idle)
  std::int64_t carried_bytes = 0;    ///< the warm start and graph kept between solves
  double flops_per_step = 0.0;       ///< one time step of one message-passing pass
  double flops_per_pass = 0.0;       ///< one pass over the horizon
  std::int64_t total_bytes() const { return problem_bytes + workspace_bytes + carried_bytes; }
};

Footprint EstimateFootprint(const ProblemShape& shape);

struct Problem;
// The shape of an existing problem.
ProblemShape ShapeOf(const Problem& problem);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_FOOTPRINT_H_
