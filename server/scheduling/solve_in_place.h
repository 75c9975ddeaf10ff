#ifndef NUPMPC_SERVER_SCHEDULING_SOLVE_IN_PLACE_H_
#define NUPMPC_SERVER_SCHEDULING_SOLVE_IN_PLACE_H_

#include <optional>

namespace nupmpc::server {

// What decides where a Control step is solved: on the gRPC thread that has it
// (WorkerPool::TryRunHere), or handed to a worker.
struct InPlaceInputs {
  double expected_cpu_ms = -1.0;  ///< the session's last solve's CPU time; negative: unknown
  double inline_max_ms = 0.0;     ///< ServerLimits.inline_solve_max_ms; 0: never in place
  double handoff_ms = 0.0;        ///< WorkerPool::handoff_ms(): what a hand-off costs here
  /// Time left before the step's deadline once its answer is sent (none: no deadline).
  std::optional<double> left_ms;
};

// A longer step is solved in place only up to this many times inline_max_ms: a reaction
// thread held for a step's deadline is held for a bounded time.
inline constexpr double kDeadlineInPlaceFactor = 10.0;

// In place when the solve is short (at most inline_max_ms: it holds the thread about as
// long as the hand-off would take), or, for a longer one of at most kDeadlineInPlaceFactor
// times that, when it has a deadline that it meets solved here but would miss after a
// hand-off. Otherwise a worker: a session's first step (no time known), steps without a
// deadline, steps the hand-off does not make late, and steps that cannot meet their
// deadline anyway (they should not hold gRPC's thread for nothing). The CPU time, not the
// wall time, of the last solve: a core shared with other threads does not make a short
// solve look long.
bool SolvesInPlace(const InPlaceInputs& in);
// Short: known, and at most inline_max_ms. A queued short step may be taken by any thread
// that holds a core (WorkerPool::Placement::kAnyCoreHolder).
bool IsShortSolve(const InPlaceInputs& in);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SCHEDULING_SOLVE_IN_PLACE_H_
