#ifndef NUPMPC_CLIENT_CLOSED_LOOP_SUMMARY_H_
#define NUPMPC_CLIENT_CLOSED_LOOP_SUMMARY_H_

// What `nupmpc closed-loop` concludes after its per-step lines: did every step converge,
// how many steps had no plan (the input was held), how long the server's solves and the
// round trips took, the worst bound violation, and what reconnects there were.

#include <map>
#include <string>
#include <vector>

#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc {

struct ClosedLoopStep {
  v1::SolveStatus status = v1::SOLVE_STATUS_UNSPECIFIED;
  double solve_ms = 0.0;       // the server's SolveResult.solve_ms
  double round_trip_ms = 0.0;  // measured by the client around Session::Step
  double max_violation = 0.0;
  // SolveResult.has_plan: false means the step's input was held, not taken from the result.
  bool has_plan = true;
};

struct ClosedLoopSummary {
  int steps = 0;
  int not_converged = 0;                               // answered steps (not HELD) whose status is not CONVERGED
  std::map<std::string, int> not_converged_by_status;  // status name → steps (with or without a plan)
  int held = 0;                                        // steps without a plan: the last input held
  int unanswered = 0;                         // of them, steps whose period ended before their answer (status HELD)
  std::map<std::string, int> held_by_status;  // status name → such steps
  double median_solve_ms = 0.0, max_solve_ms = 0.0;
  double median_round_trip_ms = 0.0, p90_round_trip_ms = 0.0;
  double max_violation = 0.0;  // over steps with a plan
  // Filled in by the caller (not from the steps): the session's reconnects, their
  // attempts and time, and the longest wall-clock time between two fresh plans (or from
  // the start to the first, or from the last to the end).
  int reconnects = 0, reconnect_attempts = 0;
  // Of the reconnects: sessions attached again by their id (warm start kept) and sessions
  // re-created from the spec (cold).
  int reattached = 0, recreated = 0;
  double reconnect_s = 0.0, longest_without_plan_s = 0.0;
  // With a control period (0: none): answers that came after their period had ended
  // (discarded; their steps count among the held ones, status "held").
  double period_ms = 0.0;
  int late_answers = 0;
};

// Median: the mean of the two middle values for an even count. p90: the nearest-rank
// percentile (the smallest value with at least 90% of the steps at or below it), so it is
// always a measured round trip. All zero for no steps.
ClosedLoopSummary SummariseClosedLoop(const std::vector<ClosedLoopStep>& steps);

// The lines printed after the table (--format table), beginning with what happened in
// words: whether every period got a plan, and if not, why none came and what the client did.
std::string SummaryText(const ClosedLoopSummary& summary);

// One JSON object on one line, marked "summary": true so that a reader of the per-step
// objects can tell it apart (--format json).
std::string SummaryJson(const ClosedLoopSummary& summary);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_CLOSED_LOOP_SUMMARY_H_
