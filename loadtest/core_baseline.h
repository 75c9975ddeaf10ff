#ifndef NUPMPC_LOADTEST_CORE_BASELINE_H_
#define NUPMPC_LOADTEST_CORE_BASELINE_H_

// The peer every load-test figure is measured against, in the same run: the core alone
// (no gRPC, no threads) solving the same closed-loop steps the streams send, with the
// same warm starts (cold at the first state, shifted after).

#include <vector>

#include "absl/status/statusor.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::loadtest {

struct CoreBaseline {
  double median_ms = 0.0;  ///< per step, including setting x[0] and shifting the warm start
  double p99_ms = 0.0;
  double mean_ms = 0.0;
  std::vector<double> state_ms;  ///< per closed-loop state, in order: its median over the rounds
  double mean_iterations = 0.0;
  int solves = 0;
};

// The core alone on the steps one load-test stream sends (LoadStream): every state in
// order, `rounds` times, each round from a cold start, and with `new_references` the same
// moving references; converted with the server's own StepUpdateFromProto, as it does.
// With `sessions` > 1, that many sessions each take every step in turn, as a server serving
// that many streams steps them: each step then finds its session's data as cold as the
// other sessions' steps in between left it (one session alone keeps it in the caches).
absl::StatusOr<CoreBaseline> MeasureCoreBaseline(const v1::ProblemSpec& spec,
                                                 const std::vector<std::vector<double>>& states, int rounds,
                                                 bool new_references = false, int sessions = 1);

// The core alone stepping `sessions` sessions of `spec` in turn, as a fleet call does
// (session s at period p gets states[(p + 7 s) % size], warm-started from its last plan),
// for `periods` timed periods from `first_period` on, after one untimed period before them
// that starts every session cold (the fleet level's warm-up leaves its cold calls out too).
// Every session's data are as cold as a fleet's leaves them (a session stepped on its own
// keeps its data in the caches between steps).
struct FleetCoreBaseline {
  double mean_ms = 0.0;  ///< per step
  double mean_iterations = 0.0;
};
absl::StatusOr<FleetCoreBaseline> MeasureFleetCore(const v1::ProblemSpec& spec,
                                                   const std::vector<std::vector<double>>& states, int sessions,
                                                   int periods, int first_period = 1);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_CORE_BASELINE_H_
