#include "client/closed_loop_summary.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "client/solve_status_name.h"

namespace nupmpc {
namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t mid = v.size() / 2;
  return v.size() % 2 == 1 ? v[mid] : 0.5 * (v[mid - 1] + v[mid]);
}

double NearestRank(std::vector<double> v, double fraction) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(fraction * static_cast<double>(v.size())));
  return v[std::clamp<std::size_t>(rank, 1, v.size()) - 1];
}

}  // namespace

ClosedLoopSummary SummariseClosedLoop(const std::vector<ClosedLoopStep>& steps) {
  ClosedLoopSummary s;
  s.steps = static_cast<int>(steps.size());
  std::vector<double> solve_ms, round_trip_ms;
  for (const ClosedLoopStep& step : steps) {
    if (step.status == v1::SOLVE_STATUS_HELD) {
      ++s.unanswered;  // no answer came in time: nothing was solved for it (as far as it knows)
    } else if (step.status != v1::SOLVE_STATUS_CONVERGED) {
      ++s.not_converged;
      ++s.not_converged_by_status[SolveStatusName(step.status)];
    }
    if (!step.has_plan) {
      ++s.held;
      ++s.held_by_status[SolveStatusName(step.status)];
    }
    if (step.status == v1::SOLVE_STATUS_HELD) continue;  // no answer: no solve or round trip to time
    solve_ms.push_back(step.solve_ms);
    round_trip_ms.push_back(step.round_trip_ms);
    s.max_solve_ms = std::max(s.max_solve_ms, step.solve_ms);
    // A result without a plan has no violation to speak of (NaN).
    if (step.has_plan && std::isfinite(step.max_violation))
      s.max_violation = std::max(s.max_violation, step.max_violation);
  }
  s.median_solve_ms = Median(solve_ms);
  s.median_round_trip_ms = Median(round_trip_ms);
  s.p90_round_trip_ms = NearestRank(round_trip_ms, 0.9);
  return s;
}

namespace {
std::string ByStatusText(const std::map<std::string, int>& by_status) {
  std::vector<std::string> parts;
  parts.reserve(by_status.size());
  for (const auto& [status, count] : by_status) parts.push_back(absl::StrCat(status, " ", count));
  return absl::StrJoin(parts, ", ");
}
std::string ByStatusJson(const std::map<std::string, int>& by_status) {
  std::vector<std::string> parts;
  parts.reserve(by_status.size());
  for (const auto& [status, count] : by_status) parts.push_back(absl::StrCat("\"", status, "\":", count));
  return absl::StrJoin(parts, ",");
}

// What happened, in one sentence.
std::string StoryText(const ClosedLoopSummary& s) {
  if (s.held == 0 && s.reconnects == 0) return "every step got its plan";
  std::vector<std::string> parts;
  if (s.unanswered > 0) {
    parts.push_back(absl::StrFormat("%d periods of %.0f ms passed without an answer and the last input was held",
                                    s.unanswered, s.period_ms));
  }
  if (const int others = s.held - s.unanswered; others > 0) {
    parts.push_back(
        absl::StrCat(others, others == 1 ? " answer" : " answers", " carried no plan and the last input was held"));
  }
  if (s.reconnects > 0) {
    const auto times = [](int n) { return absl::StrCat(n, n == 1 ? " time" : " times"); };
    parts.push_back(
        absl::StrFormat("the stream broke and the session was re-attached %s and re-created %s (%d attempts)",
                        times(s.reattached), times(s.recreated), s.reconnect_attempts));
  }
  if (s.late_answers > 0) {
    parts.push_back(
        absl::StrCat(s.late_answers, s.late_answers == 1 ? " late answer was" : " late answers were", " discarded"));
  }
  return absl::StrCat(absl::StrJoin(parts, "; "),
                      absl::StrFormat("; the longest time without a fresh plan was %.3f s", s.longest_without_plan_s));
}
}  // namespace

std::string SummaryText(const ClosedLoopSummary& s) {
  std::string convergence = s.unanswered > 0 ? "every answered step converged" : "all converged";
  if (s.not_converged > 0) {
    convergence = absl::StrCat(s.not_converged, " not converged (", ByStatusText(s.not_converged_by_status), ")");
  }
  const std::string held =
      s.held == 0 ? "0 steps" : absl::StrCat(s.held, " steps (", ByStatusText(s.held_by_status), "), last input held");
  return absl::StrFormat(
      "summary: %d steps, %s\n"
      "  what happened        %s\n"
      "  without a plan       %s\n"
      "  reconnects           %d (%d attempts, %.3f s; %d re-attached, %d re-created), longest without a fresh "
      "plan %.3f s\n"
      "  solve time (server)  median %.4f ms, max %.4f ms\n"
      "  round trip           median %.4f ms, p90 %.4f ms\n"
      "  max violation        %.3g\n",
      s.steps, convergence, StoryText(s), held, s.reconnects, s.reconnect_attempts, s.reconnect_s, s.reattached,
      s.recreated, s.longest_without_plan_s, s.median_solve_ms, s.max_solve_ms, s.median_round_trip_ms,
      s.p90_round_trip_ms, s.max_violation);
}

std::string SummaryJson(const ClosedLoopSummary& s) {
  return absl::StrFormat(
      "{\"summary\":true,\"steps\":%d,\"all_converged\":%s,\"not_converged\":{%s},\"held_steps\":%d,"
      "\"held\":{%s},\"reconnects\":%d,\"reattached\":%d,\"recreated\":%d,\"reconnect_attempts\":%d,"
      "\"reconnect_s\":%.6f,"
      "\"longest_without_plan_s\":%.6f,\"period_ms\":%.6g,\"late_answers\":%d,\"median_solve_ms\":%.6f,"
      "\"max_solve_ms\":%.6f,\"median_round_trip_ms\":%.6f,\"p90_round_trip_ms\":%.6f,\"max_violation\":%.6g}\n",
      s.steps, s.not_converged == 0 ? "true" : "false", ByStatusJson(s.not_converged_by_status), s.held,
      ByStatusJson(s.held_by_status), s.reconnects, s.reattached, s.recreated, s.reconnect_attempts, s.reconnect_s,
      s.longest_without_plan_s, s.period_ms, s.late_answers, s.median_solve_ms, s.max_solve_ms, s.median_round_trip_ms,
      s.p90_round_trip_ms, s.max_violation);
}

}  // namespace nupmpc
