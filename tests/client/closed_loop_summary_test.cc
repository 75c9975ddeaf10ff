// The summary `nupmpc closed-loop` prints after its steps.
#include "client/closed_loop_summary.h"

#include <limits>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace nupmpc {
namespace {

using ::testing::ElementsAre;
using ::testing::Pair;

ClosedLoopStep Converged(double solve_ms, double round_trip_ms, double violation = 0.0) {
  return {v1::SOLVE_STATUS_CONVERGED, solve_ms, round_trip_ms, violation};
}

TEST(ClosedLoopSummary, MediansMaximaAndNearestRankP90) {
  std::vector<ClosedLoopStep> steps;
  // Round trips 1..10 ms in scrambled order; solve times 0.1..1.0 ms.
  for (const int k : {7, 3, 10, 1, 5, 9, 2, 8, 6, 4}) steps.push_back(Converged(0.1 * k, k, 1e-12 * k));
  const ClosedLoopSummary s = SummariseClosedLoop(steps);
  EXPECT_EQ(s.steps, 10);
  EXPECT_EQ(s.not_converged, 0);
  EXPECT_DOUBLE_EQ(s.median_solve_ms, 0.55);  // even count: mean of the two middle values
  EXPECT_DOUBLE_EQ(s.max_solve_ms, 1.0);
  EXPECT_DOUBLE_EQ(s.median_round_trip_ms, 5.5);
  EXPECT_DOUBLE_EQ(s.p90_round_trip_ms, 9.0);  // the 9th of 10: a measured value
  EXPECT_DOUBLE_EQ(s.max_violation, 1e-11);
}

TEST(ClosedLoopSummary, OddCountMedianAndP90OfFewSteps) {
  const ClosedLoopSummary s = SummariseClosedLoop({Converged(3, 30), Converged(1, 10), Converged(2, 20)});
  EXPECT_DOUBLE_EQ(s.median_solve_ms, 2.0);
  EXPECT_DOUBLE_EQ(s.median_round_trip_ms, 20.0);
  EXPECT_DOUBLE_EQ(s.p90_round_trip_ms, 30.0);  // ceil(0.9 · 3) = 3rd
}

TEST(ClosedLoopSummary, CountsStepsThatDidNotConvergeByStatus) {
  const ClosedLoopSummary s = SummariseClosedLoop({Converged(1, 1),
                                                   {v1::SOLVE_STATUS_ITERATION_LIMIT, 5, 6, 0.25},
                                                   {v1::SOLVE_STATUS_TIME_LIMIT, 9, 10, 0.0},
                                                   {v1::SOLVE_STATUS_ITERATION_LIMIT, 4, 5, 0.5}});
  EXPECT_EQ(s.not_converged, 3);
  EXPECT_THAT(s.not_converged_by_status, ElementsAre(Pair("iteration_limit", 2), Pair("time_limit", 1)));
  EXPECT_DOUBLE_EQ(s.max_violation, 0.5);
  EXPECT_EQ(SummaryText(s),
            "summary: 4 steps, 3 not converged (iteration_limit 2, time_limit 1)\n"
            "  what happened        every step got its plan\n"
            "  without a plan       0 steps\n"
            "  reconnects           0 (0 attempts, 0.000 s; 0 re-attached, 0 re-created), longest without a fresh "
            "plan 0.000 s\n"
            "  solve time (server)  median 4.5000 ms, max 9.0000 ms\n"
            "  round trip           median 5.5000 ms, p90 10.0000 ms\n"
            "  max violation        0.5\n");
  EXPECT_EQ(SummaryJson(s),
            "{\"summary\":true,\"steps\":4,\"all_converged\":false,\"not_converged\":{\"iteration_limit\":2,"
            "\"time_limit\":1},\"held_steps\":0,\"held\":{},\"reconnects\":0,\"reattached\":0,\"recreated\":0,"
            "\"reconnect_attempts\":0,"
            "\"reconnect_s\":0.000000,\"longest_without_plan_s\":0.000000,\"period_ms\":0,\"late_answers\":0,"
            "\"median_solve_ms\":4.500000,\"max_solve_ms\":9.000000,\"median_round_trip_ms\":5.500000,"
            "\"p90_round_trip_ms\":10.000000,\"max_violation\":0.5}\n");
}

TEST(ClosedLoopSummary, StepsWithoutAPlanAreHeldAndCountedByStatus) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  ClosedLoopSummary s = SummariseClosedLoop({Converged(1, 1, 0.125),
                                             {v1::SOLVE_STATUS_NUMERICAL_ERROR, 2, 2, nan, /*has_plan=*/false},
                                             {v1::SOLVE_STATUS_TIME_LIMIT, 3, 3, 0.25, /*has_plan=*/true},
                                             {v1::SOLVE_STATUS_NUMERICAL_ERROR, 2, 2, 7.0, /*has_plan=*/false}});
  EXPECT_EQ(s.held, 2);
  EXPECT_THAT(s.held_by_status, ElementsAre(Pair("numerical_error", 2)));
  // With or without a plan, a step that did not converge counts by its status.
  EXPECT_EQ(s.not_converged, 3);
  EXPECT_THAT(s.not_converged_by_status, ElementsAre(Pair("numerical_error", 2), Pair("time_limit", 1)));
  EXPECT_DOUBLE_EQ(s.max_violation, 0.25);  // only plans that were applied
  s.reconnects = 3;
  s.reattached = 2;
  s.recreated = 1;
  s.reconnect_attempts = 6;
  s.reconnect_s = 1.5;
  s.longest_without_plan_s = 1.75;
  EXPECT_THAT(SummaryText(s),
              ::testing::HasSubstr(
                  "  without a plan       2 steps (numerical_error 2), last input held\n"
                  "  reconnects           3 (6 attempts, 1.500 s; 2 re-attached, 1 re-created), longest without "
                  "a fresh plan 1.750 s\n"));
  EXPECT_THAT(SummaryJson(s),
              ::testing::HasSubstr("\"held_steps\":2,\"held\":{\"numerical_error\":2},\"reconnects\":3,"
                                   "\"reattached\":2,\"recreated\":1,\"reconnect_attempts\":6,\"reconnect_s\":1.500000,"
                                   "\"longest_without_plan_s\":1.750000"));
}

TEST(ClosedLoopSummary, PeriodsWithoutAnAnswerAreHeldAndToldInWords) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const ClosedLoopStep unanswered{v1::SOLVE_STATUS_HELD, 0, 50, nan, /*has_plan=*/false};
  ClosedLoopSummary s = SummariseClosedLoop({Converged(1, 1),
                                             unanswered,
                                             unanswered,
                                             unanswered,
                                             {v1::SOLVE_STATUS_SUPERSEDED, 0, 3, nan, /*has_plan=*/false}});
  EXPECT_EQ(s.held, 4);
  EXPECT_EQ(s.unanswered, 3);
  EXPECT_EQ(s.not_converged, 1);  // the superseded one: nothing was solved for the held ones
  EXPECT_THAT(s.held_by_status, ElementsAre(Pair("held", 3), Pair("superseded", 1)));
  s.period_ms = 50;
  s.reconnects = 1;
  s.recreated = 1;
  s.reconnect_attempts = 2;
  s.late_answers = 1;
  s.longest_without_plan_s = 0.2;
  EXPECT_THAT(SummaryText(s),
              ::testing::HasSubstr("  what happened        3 periods of 50 ms passed without an answer and the last "
                                   "input was held; 1 answer carried no plan and the last input was held; the "
                                   "stream broke and the session was re-attached 0 times and re-created 1 time (2 "
                                   "attempts); 1 late answer "
                                   "was discarded; the longest time without a fresh plan was 0.200 s\n"));
  // Periods without an answer had no solve and no round trip: the medians are the answers'.
  EXPECT_DOUBLE_EQ(s.median_round_trip_ms, 2.0);
  EXPECT_THAT(SummaryJson(s), ::testing::HasSubstr("\"held_steps\":4,\"held\":{\"held\":3,\"superseded\":1}"));
  EXPECT_THAT(SummaryJson(s), ::testing::HasSubstr("\"period_ms\":50,\"late_answers\":1,"));
}

TEST(ClosedLoopSummary, AllConvergedAndNoSteps) {
  EXPECT_THAT(SummaryText(SummariseClosedLoop({Converged(1, 2)})),
              ::testing::StartsWith("summary: 1 steps, all converged\n"));
  const ClosedLoopSummary none = SummariseClosedLoop({});
  EXPECT_EQ(none.steps, 0);
  EXPECT_EQ(none.p90_round_trip_ms, 0.0);
  EXPECT_THAT(SummaryJson(none), ::testing::HasSubstr("\"all_converged\":true,\"not_converged\":{}"));
}

}  // namespace
}  // namespace nupmpc
