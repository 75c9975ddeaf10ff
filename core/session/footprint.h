#ifndef NUPMPC_CORE_SESSION_FOOTPRINT_H_
#define NUPMPC_CORE_SESSION_FOOTPRINT_H_

#include <cstdint>

#include "core/options.h"

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
  // What the priors make the session run (SelectAlgorithm). kAuto: not known, the
  // estimate is the largest over the algorithms (IFFBDD with augmented inputs included).
  Algorithm algorithm = Algorithm::kAuto;
  // Some input carries a constraint (IFFBDD then augments the state with the inputs and
  // keeps an IBFFD for the input sub-problem's polish). Assumed when unknown.
  bool inputs_constrained = true;
  // Offsets c[n] and d[n] given per step (else one or none).
  bool offsets_per_step = true;
};

// What a core::Session of that shape costs (Create, then solves), as upper bounds for the
// algorithm given (or the largest over all), with and without polish. The bytes are heap
// bytes including the allocator's per-block overhead and the transient peaks of Create
// and Solve (the eigen-decomposition of a terminal weight, Eigen's GEMM blocking for
// large M). Measured against glibc's heap in tests/core/session/footprint_test.cc: measured ≤
// estimate ≤ 3 × measured over a grid of shapes and algorithms.
struct Footprint {
  std::int64_t problem_bytes = 0;    ///< the Problem (one copy, held by the session): model matrices, priors
  std::int64_t workspace_bytes = 0;  ///< message-passing scratch (given back by ReleaseWorkspace while idle)
  // The factor graph, the warm start and iterates kept between solves, the objective's
  // trajectories, and one Solution as Solve() fills it.
  std::int64_t carried_bytes = 0;
  std::int64_t transient_bytes = 0;  ///< freed again before Create / Solve returns
  double flops_per_step = 0.0;       ///< one time step of the costliest pass (sets the interrupt's interval)
  double flops_per_pass = 0.0;       ///< one pass over the horizon
  // The peak: what must be admitted.
  std::int64_t total_bytes() const { return problem_bytes + workspace_bytes + carried_bytes + transient_bytes; }
};

Footprint EstimateFootprint(const ProblemShape& shape);

struct Problem;
// The shape of an existing problem, with the algorithm `requested` (kAuto: the one the
// priors select, as Session::Create does).
ProblemShape ShapeOf(const Problem& problem, Algorithm requested = Algorithm::kAuto);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_FOOTPRINT_H_
