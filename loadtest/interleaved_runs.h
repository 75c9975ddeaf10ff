#ifndef NUPMPC_LOADTEST_INTERLEAVED_RUNS_H_
#define NUPMPC_LOADTEST_INTERLEAVED_RUNS_H_

// Runs that compare the server under test with its peers (echo, inline, bare servers) and,
// for fleets, with separate streams and the core alone: each in turn, a round at a time, the
// order reversed every round. This VM's speed moves by tens of percent from one minute to
// the next; only figures taken in the same minutes compare.

#include <sched.h>

#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/channel_security.h"
#include "client/problem_file.h"
#include "loadtest/core_baseline.h"
#include "loadtest/echo_process.h"
#include "loadtest/fleet_level.h"
#include "loadtest/load_level.h"
#include "server/scheduling/cpu_affinity.h"

namespace nupmpc::loadtest {

// Runs `measure` on `cpus` (when given), then back on this thread's CPUs: the core alone
// is timed on the server's CPUs, where the peers run too.
template <typename Measure>
auto MeasuredOn(const std::optional<cpu_set_t>& cpus, Measure measure) -> decltype(measure()) {
  cpu_set_t own;
  CPU_ZERO(&own);
  if (!cpus.has_value() || sched_getaffinity(0, sizeof(own), &own) != 0 ||
      !nupmpc::server::PinCallingThread(*cpus).ok()) {
    return measure();
  }
  auto result = measure();
  (void)nupmpc::server::PinCallingThread(own);
  return result;
}

// One level against the server under test and each peer that runs (null: not run).
struct LevelRuns {
  LevelReport server;
  std::vector<std::optional<LevelReport>> peers;
};

// Runs the level `rounds` times against the server and each peer in turn, each run
// config.duration_s / rounds, and merges each one's runs. Peers listen in plaintext and do
// not print progress. Without peers: one run (its streams stay open throughout).
absl::StatusOr<LevelRuns> RunInterleaved(const std::string& server, const std::vector<EchoProcess*>& peers,
                                         const StreamPlan& plan, const LevelConfig& config, int rounds);

// A fleet's calls, as many separate Control streams, and the core alone stepping that many
// sessions in turn.
struct FleetRuns {
  FleetReport fleet;
  LevelReport separate;
  FleetCoreBaseline core;
};
struct FleetRunOptions {
  int sessions = 1;
  int calls_in_flight = 1;
  int rounds = 1;
  double duration_s = 5.0;  ///< in all, split over the rounds
  double warmup_s = 0.5;
  int baseline_rounds = 20;  ///< the core's periods in all: at least this and one per closed-loop state
};

// The three, `rounds` times each, in turn: calls and streams duration_s / rounds each; the
// core's rounds time consecutive periods.
absl::StatusOr<FleetRuns> RunFleetInterleaved(const std::string& target, const ChannelSecurity& security,
                                              const StreamPlan& plan, const ProblemFile& file,
                                              const FleetRunOptions& options,
                                              const std::optional<cpu_set_t>& server_cpus);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_INTERLEAVED_RUNS_H_
