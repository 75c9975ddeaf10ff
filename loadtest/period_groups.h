#ifndef NUPMPC_LOADTEST_PERIOD_GROUPS_H_
#define NUPMPC_LOADTEST_PERIOD_GROUPS_H_

// Groups of Control streams with control periods, as controllers run them: each stream a
// nupmpc::Session with a ControlPeriod, stepped at its period (never faster), counting for
// every step whether a plan came in time. The figure of merit of a control service: how
// many periods got a usable plan by their deadline, per group, and how evenly the streams
// of a group were served (nupmpc-period-groups, deploy/deadline-sweep.py).

#include <chrono>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::loadtest {

struct PeriodGroup {
  std::string name;
  v1::ProblemSpec spec;
  std::vector<std::vector<double>> states;  ///< cycled through (at least one)
  int streams = 1;
  std::chrono::microseconds period{10000};
};

// What one group's steps came to. Every step is exactly one of: met (a plan by its
// deadline), queued past its deadline or too long a solve (the server's
// SolveResult.deadline), held (no answer within the period: the client's), superseded or
// without a plan for another reason (other), an error.
struct GroupFigures {
  std::string name;
  int streams = 0;
  double period_ms = 0.0;
  long steps = 0, met = 0, queued_past_deadline = 0, solve_too_long = 0, held = 0, other = 0, errors = 0;
  double slack_p50_ms = 0.0, slack_p01_ms = 0.0;  ///< of answered steps; p01: the worst 1 %
  // Deadlines met by the group's least and most served stream over its mean (1 and 1: even).
  double stream_min_share = 0.0, stream_max_share = 0.0;
  double missed_share() const { return steps > 0 ? 1.0 - static_cast<double>(met) / static_cast<double>(steps) : 0.0; }
};

// Runs every group's streams against `target` for `duration` (after `warmup`, not
// counted), each stream on a connection of its own.
absl::StatusOr<std::vector<GroupFigures>> RunPeriodGroups(const std::string& target,
                                                          const std::vector<PeriodGroup>& groups,
                                                          std::chrono::milliseconds duration,
                                                          std::chrono::milliseconds warmup);

// Steps per second the server gives `streams` streams of `group`'s instance stepping as
// fast as answers come for `duration`: its capacity for that instance (enough streams that
// the round trips overlap and the server's cores, not one stream's latency, set the rate).
absl::StatusOr<double> CalibrateStepsPerSecond(const std::string& target, const PeriodGroup& group,
                                               std::chrono::milliseconds duration, int streams = 8);

// One JSON object per group, on one line each.
std::string GroupFiguresJson(const GroupFigures& figures);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_PERIOD_GROUPS_H_
