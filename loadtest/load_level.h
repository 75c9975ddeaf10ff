#ifndef NUPMPC_LOADTEST_LOAD_LEVEL_H_
#define NUPMPC_LOADTEST_LOAD_LEVEL_H_

// One load level of nupmpc-loadtest: C concurrent Control streams against a server for a
// fixed time (or request count), closed or open loop.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/channel_security.h"
#include "loadtest/load_stream.h"

namespace nupmpc::loadtest {

struct LevelConfig {
  int concurrency = 1;
  bool closed_loop = true;
  double rate_per_s = 0.0;     ///< open loop: total Poisson arrival rate over all streams
  double duration_s = 5.0;     ///< measured window
  double warmup_s = 0.5;       ///< before the window; not counted
  std::uint64_t requests = 0;  ///< > 0: stop once this many solves were answered
  bool progress = false;       ///< a status line on stderr every second
  std::uint64_t seed = 1;
  ChannelSecurity security;  ///< TLS / token of the server under test
};

// The core alone on a level's steps, with as many sessions stepped in turn as the level
// has streams: the inline peer's busy time per step.
struct LevelCore {
  double median_ms = 0.0;
  double mean_ms = 0.0;
  double busy_mean_ms = 0.0;  ///< what the inline peer spins per step on average (per-state medians)
  int sessions = 0;           ///< 0: not measured
};

struct LevelReport {
  LevelConfig config;
  double measured_s = 0.0;
  StreamTally tally;
  double solves_per_s = 0.0;
  double p50_ms = 0.0, p90_ms = 0.0, p99_ms = 0.0, p999_ms = 0.0, max_ms = 0.0;
  double service_p50_ms = 0.0, service_p99_ms = 0.0;  ///< from the hand-over to gRPC
  double solve_p50_ms = 0.0;                          ///< the server's own solver time, median
  double mean_iterations = 0.0;
  // Answered solves of the least and the most served stream over the mean of all streams
  // (1 and 1 when every stream got the same): how evenly the server shared its cores.
  double stream_min_share = 0.0, stream_max_share = 0.0;
  // The same level against the zero-work echo server (EchoControlServer), against the
  // echo busy for the core's median solve time in its reaction, and against the bare
  // server that really solves in its reaction (EchoControlServer::StartSolving), when run.
  std::shared_ptr<const LevelReport> echo, inline_solve, bare;
  LevelCore inline_core;
};

// Opens the streams (each creates its session), runs the level, closes them.
absl::StatusOr<LevelReport> RunLevel(const std::string& target, const StreamPlan& plan, const LevelConfig& config);

// Recomputes the rates and quantiles of `report` from its tally and measured_s.
void Summarize(LevelReport& report);

// One report of several runs of the same level against the same target (rounds
// interleaved with the peers' runs): tallies and measured time summed, quantiles over all
// answers, the least and the most served stream of any round.
LevelReport MergeRounds(const std::vector<LevelReport>& rounds);

// A closed-loop level starved a stream when its least-served stream got under half the mean
// or its most served over twice the mean (in any round): every stream asks for its next step
// only once answered, so a fair server serves them alike. Open-loop levels are not judged:
// there a stream's answers also depend on which of its arrivals were superseded or refused;
// nor levels with under kMinAnswersToJudge answers per stream, whose shares are mostly
// counting noise.
inline constexpr double kFairShareFactor = 2.0;
inline constexpr double kMinAnswersToJudge = 20.0;
bool StarvedAStream(const LevelReport& level);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_LOAD_LEVEL_H_
