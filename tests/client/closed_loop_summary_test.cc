// The summary `nupmpc closed-loop` prints after its steps.
#include "client/closed_loop_summary.h"

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
            "  solve time (server)  median 4.5000 ms, max 9.0000 ms\n"
            "  round trip           median 5.5000 ms, p90 10.0000 ms\n"
            "  max violation        0.5\n");
  EXPECT_EQ(SummaryJson(s),
            "{\"summary\":true,\"steps\":4,\"all_converged\":false,\"not_converged\":{\"iteration_limit\":2,"
            "\"time_limit\":1},\"median_solve_ms\":4.500000,\"max_solve_ms\":9.000000,\"median_round_trip_ms\":5.500000,"
            "\"p90_round_trip_ms\":10.000000,\"max_violation\":0.5}\n");
}

TEST(ClosedLoopSummary, AllConvergedAndNoSteps) {
  EXPECT_THAT(SummaryText(SummariseClosedLoop({Converged(1, 2)})), ::testing::StartsWith("summary: 1 steps, all converged\n"));
  const ClosedLoopSummary none = SummariseClosedLoop({});
  EXPECT_EQ(none.steps, 0);
  EXPECT_EQ(none.p90_round_trip_ms, 0.0);
  EXPECT_THAT(SummaryJson(none), ::testing::HasSubstr("\"all_converged\":true,\"not_converged\":{}"));
}

}  // namespace
}  // namespace nupmpc
