#ifndef NUPMPC_CORE_SESSION_MPC_SESSION_H_
#define NUPMPC_CORE_SESSION_MPC_SESSION_H_

// What a long-lived controller needs from a solver, whatever the problem class: a problem
// of fixed shape whose values change between solves, a warm start carried from one solve
// to the next, and solves under limits. Implemented by Session (linear problems) and by
// KeepOutSession (a linear plant with keep-out regions, solved by sequential
// linearisation). The service holds every session through this interface.
//
// Thread safety: none; one thread uses a session at a time.

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/options.h"
#include "core/problem.h"
#include "core/solution.h"

namespace nupmpc::core {

class MpcSession {
 public:
  virtual ~MpcSession() = default;

  // The problem in the caller's terms (what Update() replaces).
  virtual const Problem& problem() const = 0;
  virtual Algorithm algorithm() const = 0;

  virtual absl::Status SetInitialState(const Eigen::VectorXd& x0) = 0;
  // Replaces the problem's values; the shape must match (FAILED_PRECONDITION otherwise).
  // A rejected problem leaves the session as it was.
  virtual absl::Status Update(const Problem& problem) = 0;

  // Receding horizon: the carried warm start moves one step earlier.
  virtual void ShiftWarmStart() = 0;
  // For idle sessions: frees scratch memory, keeps problem and warm start.
  virtual void ReleaseWorkspace() = 0;

  // The limits' time limit and cancel flag are honoured inside the passes too (a solve
  // returns within about one time step of a pass after either). SolveSummary.has_plan says
  // whether `solution` holds a plan of this solve for the current x[0]; if not, its
  // matrices are empty and the session stays usable.
  virtual absl::StatusOr<SolveSummary> Solve(const SolveLimits& limits, Solution* solution) = 0;
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_MPC_SESSION_H_
