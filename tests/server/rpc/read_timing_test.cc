// When a Control stream reads its next step (server/rpc/read_timing.h): ahead of an in-place
// solve until the client shows it waits for its answers, then after (but for a probe every
// kProbeSteps steps), and ahead again at the first sign of a step sent before its answer.
#include "server/rpc/read_timing.h"

#include "gtest/gtest.h"

namespace nupmpc::server {
namespace {

using std::chrono::microseconds;
using std::chrono::milliseconds;

// A closed loop's step: nothing being solved, its read pending for a round trip.
void ClosedLoopStep(ReadTiming& t, bool read_after) { t.StepArrived(false, read_after, milliseconds(1), false); }

ReadTiming AfterAClosedLoop() {
  ReadTiming t;
  for (int i = 0; i < ReadTiming::kClosedLoopSteps; ++i) ClosedLoopStep(t, /*read_after=*/false);
  return t;
}

TEST(ReadTiming, AStreamStartsReadingAhead) { EXPECT_TRUE(ReadTiming().ahead()); }

TEST(ReadTiming, ItReadsAfterTheSolveOnceItsClientWaitedForItsAnswersSeveralStepsInARow) {
  ReadTiming t;
  for (int i = 1; i < ReadTiming::kClosedLoopSteps; ++i) {
    ClosedLoopStep(t, false);
    EXPECT_TRUE(t.ahead()) << "after " << i << " closed-loop steps";
  }
  ClosedLoopStep(t, false);
  EXPECT_FALSE(t.ahead());
  for (int i = 0; i < 10; ++i) ClosedLoopStep(t, /*read_after=*/true);  // and stays there
  EXPECT_FALSE(t.ahead());
}

TEST(ReadTiming, AStepArrivingDuringASolveSendsItBackAheadForAsLongAgain) {
  ReadTiming t = AfterAClosedLoop();
  t.StepArrived(/*solving=*/true, false, milliseconds(1), false);
  EXPECT_TRUE(t.ahead());
  for (int i = 1; i < ReadTiming::kClosedLoopSteps; ++i) ClosedLoopStep(t, false);
  EXPECT_TRUE(t.ahead());  // the count started over
  ClosedLoopStep(t, false);
  EXPECT_FALSE(t.ahead());
}

TEST(ReadTiming, AStepAReadAfterTheSolveFindsAlreadyThereSendsItBackAhead) {
  ReadTiming t = AfterAClosedLoop();
  t.StepArrived(false, /*read_after=*/true, ReadTiming::kAlreadyThere - microseconds(1), false);
  EXPECT_TRUE(t.ahead());
}

TEST(ReadTiming, AStepArrivingBeforeItsPredecessorsAnswerWasWrittenSendsItBackAhead) {
  ReadTiming t = AfterAClosedLoop();
  t.StepArrived(false, /*read_after=*/true, milliseconds(5), /*answer_unsent=*/true);
  EXPECT_TRUE(t.ahead());
}

TEST(ReadTiming, OnlyAReadStartedAfterASolveIsJudgedByHowSoonItCompletes) {
  // A read started ahead waits through the solve: how soon it completes says nothing.
  ReadTiming t;
  for (int i = 0; i < ReadTiming::kClosedLoopSteps; ++i)
    t.StepArrived(false, /*read_after=*/false, microseconds(1), false);
  EXPECT_FALSE(t.ahead());
  ClosedLoopStep(t, /*read_after=*/true);
  EXPECT_FALSE(t.ahead());  // a read after the solve that waited for the client: a closed loop
}

TEST(ReadTiming, AStepArrivingBeforeAnAnswerWasWrittenCountsWhereverItsReadStarted) {
  ReadTiming t;
  for (int i = 0; i < 3 * ReadTiming::kClosedLoopSteps; ++i) {
    t.StepArrived(false, /*read_after=*/false, milliseconds(1), /*answer_unsent=*/true);
  }
  EXPECT_TRUE(t.ahead());  // a burst read ahead never looks like a closed loop
}

TEST(ReadTiming, ReadingAheadEveryStepWhileAheadAndEveryProbeStepsWhileAfter) {
  ReadTiming t;
  for (int i = 0; i < 3 * ReadTiming::kProbeSteps; ++i) EXPECT_TRUE(t.ReadAhead()) << i;
  t = AfterAClosedLoop();
  for (int round = 0; round < 3; ++round) {
    for (int i = 1; i < ReadTiming::kProbeSteps; ++i) EXPECT_FALSE(t.ReadAhead()) << round << ", " << i;
    EXPECT_TRUE(t.ReadAhead()) << "the probe of round " << round;
  }
  // A probe's read is ahead: the step arriving during its solve sends the stream back ahead.
  t.StepArrived(/*solving=*/true, /*read_after=*/false, microseconds(50), false);
  EXPECT_TRUE(t.ahead());
  EXPECT_TRUE(t.ReadAhead());
}

}  // namespace
}  // namespace nupmpc::server
