#ifndef NUPMPC_LOADTEST_FLEET_LEVEL_H_
#define NUPMPC_LOADTEST_FLEET_LEVEL_H_

// nupmpc-loadtest --fleet S: S sessions stepped together, one SolveFleet call per period
// (closed loop: the next call when the answer arrives), each session cycling through the
// instance's closed-loop states from its own offset; with --fleet_calls_in_flight K, the S
// sessions in K calls of S/K, each caller closed-loop on its own.

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/channel_security.h"
#include "loadtest/load_stream.h"

namespace nupmpc::loadtest {

struct FleetReport {
  int sessions = 0;
  int calls_in_flight = 1;  ///< callers stepping their share of the sessions at once
  double measured_s = 0.0;
  std::uint64_t calls = 0;
  std::uint64_t answered = 0;  ///< steps answered with a result (solved or superseded)
  double steps_per_s = 0.0;    ///< answered / measured_s
  double call_p50_ms = 0.0, call_p99_ms = 0.0;
  std::uint64_t step_errors = 0;  ///< answers with an error code
  std::uint64_t solved = 0;       ///< answers with a result that solved (not superseded)
  std::uint64_t iterations = 0;   ///< the solved steps' iterations, summed
  double mean_iterations = 0.0;   ///< iterations / solved
  std::vector<double> call_ms;    ///< every measured call's round trip
};

// `calls_in_flight` callers, each on a connection of its own, step their share of the
// sessions (as equal as can be) one call after another, at the same time: with more than
// one, the server has the next call while a caller handles its answer.
absl::StatusOr<FleetReport> RunFleetLevel(const std::string& target, const ChannelSecurity& security,
                                          const StreamPlan& plan, int sessions, int calls_in_flight, double duration_s,
                                          double warmup_s);

// One report of several runs (rounds interleaved with the peers'): calls, answers and
// measured time summed, quantiles over every call, iterations over every solved step.
FleetReport MergeFleetRounds(const std::vector<FleetReport>& rounds);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_FLEET_LEVEL_H_
