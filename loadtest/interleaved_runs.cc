#include "loadtest/interleaved_runs.h"

#include <algorithm>

#include "absl/strings/str_cat.h"

namespace nupmpc::loadtest {
namespace {

// `status` with `what` before its message.
absl::Status Prefixed(const absl::Status& status, absl::string_view what) {
  return absl::Status(status.code(), absl::StrCat(what, ": ", status.message()));
}

}  // namespace

absl::StatusOr<LevelRuns> RunInterleaved(const std::string& server, const std::vector<EchoProcess*>& peers,
                                         const StreamPlan& plan, const LevelConfig& config, int rounds) {
  // Slot 0 is the server under test, 1.. the peers.
  std::vector<std::vector<LevelReport>> runs(peers.size() + 1);
  std::vector<int> order;
  for (int slot = 0; slot <= static_cast<int>(peers.size()); ++slot) {
    if (slot == 0 || peers[slot - 1] != nullptr) order.push_back(slot);
  }
  rounds = order.size() > 1 ? std::max(1, rounds) : 1;
  LevelConfig round_config = config;
  round_config.duration_s = config.duration_s / rounds;
  round_config.requests = (config.requests + rounds - 1) / rounds;
  for (int round = 0; round < rounds; ++round) {
    for (const int slot : order) {
      LevelConfig run_config = round_config;
      if (slot > 0) {
        run_config.progress = false;
        run_config.security = {};
      }
      const std::string& target = slot == 0 ? server : peers[slot - 1]->target();
      absl::StatusOr<LevelReport> run = RunLevel(target, plan, run_config);
      if (!run.ok()) return Prefixed(run.status(), slot == 0 ? "server under test" : "peer");
      runs[slot].push_back(*std::move(run));
    }
    std::reverse(order.begin(), order.end());
  }
  LevelRuns merged{.server = MergeRounds(runs[0]), .peers = {}};
  for (std::size_t i = 1; i < runs.size(); ++i) {
    merged.peers.push_back(runs[i].empty() ? std::nullopt : std::optional(MergeRounds(runs[i])));
  }
  return merged;
}

absl::StatusOr<FleetRuns> RunFleetInterleaved(const std::string& target, const ChannelSecurity& security,
                                              const StreamPlan& plan, const ProblemFile& file,
                                              const FleetRunOptions& options,
                                              const std::optional<cpu_set_t>& server_cpus) {
  const int rounds = std::max(1, options.rounds);
  const double duration_s = options.duration_s / rounds;
  const int all_periods = std::max(options.baseline_rounds, static_cast<int>(file.closed_loop_states.size()));
  const int periods = std::max(1, (all_periods + rounds - 1) / rounds);
  std::vector<FleetReport> fleet;
  std::vector<LevelReport> separate;
  std::vector<FleetCoreBaseline> core;
  std::vector<int> order = {0, 1, 2};
  for (int round = 0; round < rounds; ++round) {
    for (const int run : order) {
      if (run == 0) {
        absl::StatusOr<FleetReport> stepped = RunFleetLevel(target, security, plan, options.sessions,
                                                            options.calls_in_flight, duration_s, options.warmup_s);
        if (!stepped.ok()) return Prefixed(stepped.status(), "fleet");
        fleet.push_back(*std::move(stepped));
      } else if (run == 1) {
        LevelConfig config;
        config.concurrency = options.sessions;
        config.duration_s = duration_s;
        config.warmup_s = options.warmup_s;
        config.security = security;
        absl::StatusOr<LevelReport> streams = RunLevel(target, plan, config);
        if (!streams.ok()) return Prefixed(streams.status(), "separate streams");
        separate.push_back(*std::move(streams));
      } else {
        absl::StatusOr<FleetCoreBaseline> in_turn = MeasuredOn(server_cpus, [&] {
          return MeasureFleetCore(file.spec, file.closed_loop_states, options.sessions, periods, 1 + round * periods);
        });
        if (!in_turn.ok()) return Prefixed(in_turn.status(), "fleet core baseline");
        core.push_back(*in_turn);
      }
    }
    std::reverse(order.begin(), order.end());
  }
  FleetRuns merged{.fleet = MergeFleetRounds(fleet), .separate = MergeRounds(separate), .core = {}};
  for (const FleetCoreBaseline& c : core) {  // the same number of periods each
    merged.core.mean_ms += c.mean_ms / static_cast<double>(core.size());
    merged.core.mean_iterations += c.mean_iterations / static_cast<double>(core.size());
  }
  return merged;
}

}  // namespace nupmpc::loadtest
