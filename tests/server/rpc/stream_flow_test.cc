// The flow control of a Control stream without gRPC (server/rpc/stream_flow.h): newest state
// wins (one step solved, one parked, a newer one supersedes it), reading pauses while the
// client leaves max_answers answers unread, and the stream finishes only once nothing is
// under way.
#include "server/rpc/stream_flow.h"

#include <optional>
#include <string>
#include <utility>

#include "gtest/gtest.h"

namespace nupmpc::server {
namespace {

using Flow = StreamFlow<int, std::string>;  // a step is its sequence number, an answer its text
using Clock = Flow::Clock;

constexpr int kMaxAnswers = 2;

// A stream whose first message attached it to its session.
Flow Opened() {
  Flow flow;
  EXPECT_EQ(flow.MessageArrived(), Flow::Arrival::kFirst);
  flow.Opened();
  return flow;
}

// What Pump says, and the answer it hands out to write ("" if none).
std::pair<Flow::Next, std::string> PumpOnce(Flow& flow) {
  const std::string* to_write = nullptr;
  const Flow::Next next = flow.Pump(&to_write);
  return {next, to_write != nullptr ? *to_write : std::string()};
}

TEST(StreamFlow, TheFirstMessageAttachesLaterOnesAreSteps) {
  Flow flow;
  EXPECT_EQ(flow.phase(), Flow::Phase::kAwaitingFirst);
  EXPECT_EQ(flow.MessageArrived(), Flow::Arrival::kFirst);
  EXPECT_EQ(flow.phase(), Flow::Phase::kAttaching);
  flow.Opened();
  EXPECT_EQ(flow.MessageArrived(), Flow::Arrival::kStep);
  EXPECT_EQ(flow.MessageArrived(), Flow::Arrival::kStep);
}

TEST(StreamFlow, AStepIsSolvedAtOnceWhenNoneIsAndParkedWhileOneIs) {
  Flow flow = Opened();
  const Clock::time_point t1 = Clock::now();
  EXPECT_FALSE(flow.Park(1, t1).has_value());
  EXPECT_EQ(flow.TakeParked(), 1);
  EXPECT_TRUE(flow.solving());
  EXPECT_EQ(flow.solving_received_at(), t1);
  EXPECT_FALSE(flow.Park(2, t1 + std::chrono::milliseconds(1)).has_value());
  EXPECT_FALSE(flow.TakeParked().has_value()) << "one step solved at a time";
  flow.SolveEnded();
  EXPECT_EQ(flow.TakeParked(), 2);
  EXPECT_EQ(flow.solving_received_at(), t1 + std::chrono::milliseconds(1)) << "its deadline counts from its arrival";
}

TEST(StreamFlow, ANewerStepSupersedesTheParkedOne) {
  Flow flow = Opened();
  ASSERT_EQ(flow.Park(1, Clock::now()), std::nullopt);
  ASSERT_EQ(flow.TakeParked(), 1);
  EXPECT_EQ(flow.Park(2, Clock::now()), std::nullopt);
  EXPECT_EQ(flow.Park(3, Clock::now()), 2);  // answered as superseded by the reactor
  EXPECT_EQ(flow.Park(4, Clock::now()), 3);
  flow.SolveEnded();
  EXPECT_EQ(flow.TakeParked(), 4) << "newest state wins";
  flow.SolveEnded();
  EXPECT_FALSE(flow.TakeParked().has_value());
}

TEST(StreamFlow, AnswersAreWrittenOneAtATimeInOrder) {
  Flow flow = Opened();
  EXPECT_TRUE(flow.answers_idle());
  flow.QueueAnswer("a");
  flow.QueueAnswer("b");
  EXPECT_FALSE(flow.answers_idle());
  EXPECT_EQ(PumpOnce(flow), std::make_pair(Flow::Next::kWrite, std::string("a")));
  EXPECT_TRUE(flow.writing());
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kNothing) << "a is still being written";
  EXPECT_FALSE(flow.WriteDone(/*ok=*/true, kMaxAnswers));
  EXPECT_EQ(PumpOnce(flow), std::make_pair(Flow::Next::kWrite, std::string("b")));
  EXPECT_FALSE(flow.WriteDone(true, kMaxAnswers));
  EXPECT_TRUE(flow.answers_idle());
}

TEST(StreamFlow, ReadingPausesWhileMaxAnswersWaitAndResumesOnceOneIsWritten) {
  Flow flow = Opened();
  bool paused_now = false;
  EXPECT_TRUE(flow.ShouldRead(kMaxAnswers, &paused_now));
  EXPECT_FALSE(paused_now);
  for (int i = 0; i < kMaxAnswers; ++i) flow.QueueAnswer("answer");
  EXPECT_FALSE(flow.ShouldRead(kMaxAnswers, &paused_now));
  EXPECT_TRUE(paused_now) << "the pause is counted once";
  EXPECT_FALSE(flow.ShouldRead(kMaxAnswers, &paused_now));
  EXPECT_FALSE(paused_now);
  ASSERT_EQ(PumpOnce(flow).first, Flow::Next::kWrite);
  EXPECT_TRUE(flow.WriteDone(/*ok=*/true, kMaxAnswers)) << "one fewer waits: reading resumes";
  ASSERT_EQ(PumpOnce(flow).first, Flow::Next::kWrite);
  EXPECT_FALSE(flow.WriteDone(true, kMaxAnswers)) << "reading was not paused: nothing to resume";
}

TEST(StreamFlow, AStreamWhoseClientHalfClosedFinishesOnceNothingIsUnderWay) {
  Flow flow = Opened();
  flow.ReadDecided();
  ASSERT_EQ(flow.Park(1, Clock::now()), std::nullopt);
  ASSERT_EQ(flow.TakeParked(), 1);
  EXPECT_FALSE(flow.ReadStarted()) << "the client still sends: no reason to pump";
  flow.ReadingDone();
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kNothing) << "a step is being solved";
  flow.QueueAnswer("1");
  flow.SolveEnded();
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kWrite);
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kNothing) << "its answer is being written";
  flow.WriteDone(true, kMaxAnswers);
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kFinish);
  EXPECT_EQ(flow.phase(), Flow::Phase::kFinished);
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kNothing) << "finished once";
}

TEST(StreamFlow, AHalfClosedStreamSolvesItsParkedStepBeforeItFinishes) {
  Flow flow = Opened();
  ASSERT_EQ(flow.Park(1, Clock::now()), std::nullopt);
  ASSERT_EQ(flow.TakeParked(), 1);
  ASSERT_EQ(flow.Park(2, Clock::now()), std::nullopt);
  flow.ReadingDone();
  flow.SolveEnded();
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kNothing) << "step 2 waits to be solved";
  EXPECT_EQ(flow.TakeParked(), 2);
  flow.SolveEnded();
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kFinish);
}

TEST(StreamFlow, AReadDecidedOnButNotStartedHoldsTheFinishBack) {
  Flow flow = Opened();
  flow.ReadDecided();
  flow.End();
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kNothing) << "no read may start after the finish";
  EXPECT_TRUE(flow.ReadStarted()) << "an ending stream pumps once its read has started";
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kFinish);
}

TEST(StreamFlow, AnEndingStreamStopsReadingWritesWhatIsQueuedThenFinishes) {
  Flow flow = Opened();
  flow.QueueAnswer("last");
  flow.End();
  bool paused_now = false;
  EXPECT_FALSE(flow.ShouldRead(kMaxAnswers, &paused_now));
  EXPECT_EQ(flow.MessageArrived(), Flow::Arrival::kDropped);
  EXPECT_EQ(PumpOnce(flow), std::make_pair(Flow::Next::kWrite, std::string("last")));
  flow.WriteDone(true, kMaxAnswers);
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kFinish);
}

TEST(StreamFlow, AStreamIsNotFinishedWhileItsSessionIsBeingBuilt) {
  Flow flow;
  ASSERT_EQ(flow.MessageArrived(), Flow::Arrival::kFirst);
  flow.Attaching();
  flow.ReadingDone();  // the client half-closed right after its first message
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kNothing);
  EXPECT_FALSE(flow.Revoke()) << "the phase is not the revocation's to change while attaching";
  EXPECT_FALSE(flow.EndWithoutFirstMessage()) << "the first message arrived";
  flow.Opened();
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kFinish);
}

TEST(StreamFlow, TheFirstMessagesTimerEndsOnlyAStreamStillWaitingForIt) {
  Flow waiting;
  EXPECT_TRUE(waiting.EndWithoutFirstMessage());
  EXPECT_EQ(waiting.phase(), Flow::Phase::kEnding);
  EXPECT_EQ(waiting.MessageArrived(), Flow::Arrival::kDropped) << "a late first message is dropped";
  Flow open = Opened();
  EXPECT_FALSE(open.EndWithoutFirstMessage());
  EXPECT_EQ(open.phase(), Flow::Phase::kOpen);
}

TEST(StreamFlow, ARevokedStreamDropsItsParkedStepButAnswersTheOneBeingSolved) {
  Flow flow = Opened();
  ASSERT_EQ(flow.Park(1, Clock::now()), std::nullopt);
  ASSERT_EQ(flow.TakeParked(), 1);
  ASSERT_EQ(flow.Park(2, Clock::now()), std::nullopt);
  EXPECT_TRUE(flow.Revoke());
  EXPECT_FALSE(flow.Revoke()) << "once";
  flow.SolveEnded();
  EXPECT_FALSE(flow.TakeParked().has_value()) << "the parked step was dropped";
  flow.QueueAnswer("1");
  EXPECT_EQ(PumpOnce(flow), std::make_pair(Flow::Next::kWrite, std::string("1")));
  flow.WriteDone(true, kMaxAnswers);
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kFinish);
}

TEST(StreamFlow, AFailedWriteDropsWhatIsLeftAndStopsReading) {
  Flow flow = Opened();
  for (int i = 0; i < kMaxAnswers; ++i) flow.QueueAnswer("answer");
  bool paused_now = false;
  ASSERT_FALSE(flow.ShouldRead(kMaxAnswers, &paused_now));
  ASSERT_EQ(flow.Park(1, Clock::now()), std::nullopt);
  ASSERT_EQ(PumpOnce(flow).first, Flow::Next::kWrite);
  EXPECT_FALSE(flow.WriteDone(/*ok=*/false, kMaxAnswers)) << "the client is gone: no more reads";
  EXPECT_TRUE(flow.answers_idle());
  EXPECT_FALSE(flow.TakeParked().has_value());
  EXPECT_FALSE(flow.ShouldRead(kMaxAnswers, &paused_now));
  EXPECT_EQ(PumpOnce(flow).first, Flow::Next::kFinish);
}

}  // namespace
}  // namespace nupmpc::server
