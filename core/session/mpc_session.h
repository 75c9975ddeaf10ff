#ifndef NUPMPC_CORE_SESSION_MPC_SESSION_H_
#define NUPMPC_CORE_SESSION_MPC_SESSION_H_

// What a long-lived controller needs from a solver, whatever the problem class: a problem
// of fixed shape whose values change between solves (one StepUpdate per control period),
// a warm start carried from one solve to the next, and solves under limits. Implemented
// by Session (linear problems), KeepOutSession (a linear plant with keep-out regions,
// solved by sequential linearisation), gp::GpMpcSession (a GP model) and
// InputMappedSession (multi-level inputs or input differences around any of them). The
// service holds every session through this interface and steps all of them the same way.
//
// Thread safety: none; one thread uses a session at a time.

#include <string>
#include <string_view>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/options.h"
#include "core/problem.h"
#include "core/session/step_update.h"
#include "core/solution.h"

namespace nupmpc::core {

// A session's sizes in the caller's terms.
struct Dimensions {
  int num_states = 0, num_inputs = 0, num_outputs = 0, horizon = 0;
};
inline Dimensions DimensionsOf(const Problem& p) { return {p.num_states, p.num_inputs, p.num_outputs, p.horizon}; }

class MpcSession {
 public:
  virtual ~MpcSession() = default;

  // The problem the solver works on (for an InputMappedSession the expanded or augmented
  // one; dimensions() gives the caller's).
  virtual const Problem& problem() const = 0;
  virtual Algorithm algorithm() const = 0;
  // The caller's dimensions: the sizes of Apply()'s vectors and of Solve()'s plan.
  virtual Dimensions dimensions() const { return DimensionsOf(problem()); }

  virtual absl::Status SetInitialState(const Eigen::VectorXd& x0) = 0;
  // One control period's changes (core/session/step_update.h), checked completely before
  // anything changes: a rejected update leaves the session as it was, and the message
  // names the StepUpdate field. An update never copies the session's model.
  virtual absl::Status Apply(const StepUpdate& update) = 0;

  // Receding horizon: the carried warm start moves one step earlier.
  virtual void ShiftWarmStart() = 0;
  // For idle sessions: frees scratch memory, keeps problem and warm start.
  virtual void ReleaseWorkspace() = 0;

  // The limits' time limit and cancel flag are honoured inside the passes too (a solve
  // returns within about one time step of a pass after either). SolveSummary.has_plan says
  // whether `solution` holds a plan of this solve for the current x[0]; if not, its
  // matrices are empty and the session stays usable.
  virtual absl::StatusOr<SolveSummary> Solve(const SolveLimits& limits, Solution* solution) = 0;

  // Snapshots (core/snapshot/state_archive.h): the session's current values (its problem
  // after every update, x[0] included) and the warm start its next solve starts from. A
  // session built from the same creation spec and restored from these bytes gives
  // bit-identical plans with the same pass counts as the original would have.
  // SaveState appends to `out`. RestoreState answers INVALID_ARGUMENT naming the field when
  // the bytes do not fit this session (another spec, another format version, truncated or
  // altered bytes); the session must then be discarded (it may be half restored).
  // Every kind the service builds implements them; the defaults (UNIMPLEMENTED) are for
  // kinds added later.
  virtual absl::Status SaveState(std::string* out) {
    (void)out;
    return absl::UnimplementedError("this session kind has no snapshot");
  }
  virtual absl::Status RestoreState(std::string_view bytes) {
    (void)bytes;
    return absl::UnimplementedError("this session kind has no snapshot");
  }
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SESSION_MPC_SESSION_H_
