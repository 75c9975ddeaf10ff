// A Session with a control period (client/session.h) against a scripted Control service on
// a real gRPC server in this process: the test decides when (or whether) each step is
// answered, so the mechanisms are checked without depending on the machine's speed: a step
// returns HELD by its period plus a generous slack, a late answer is never returned for a
// later step and still updates the spec, K held periods in a row re-create the session, and
// without a period a step waits for its answer.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "client/client.h"
#include "gtest/gtest.h"
#include "tests/client/scripted_control.h"

namespace nupmpc {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;
using testing::ScriptedControl;

// Tests allow this much beyond the period: a loaded two-core machine may be slow to wake a
// thread, and what is checked is that a step does not wait for its answer, not how fast.
constexpr milliseconds kSlack(400);

class ControlPeriodTest : public ::testing::Test {
 protected:
  void SetUp() override {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(&service_);
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    client_ = std::make_unique<Client>("127.0.0.1:" + std::to_string(port_));
    spec_.mutable_initial_state()->add_mean(0.0);
  }
  void TearDown() override {
    client_.reset();
    server_->Shutdown(std::chrono::system_clock::now() + milliseconds(100));
  }

  static v1::Step StepAt(double x0) {
    v1::Step step;
    step.add_state(x0);
    return step;
  }

  ScriptedControl service_;
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<Client> client_;
  v1::ProblemSpec spec_;
};

TEST_F(ControlPeriodTest, AStepWithoutItsAnswerInThePeriodIsHeldAndItsLateAnswerIsNeverReturned) {
  const milliseconds period(100);
  // Step 1 is answered three periods late; every other at once.
  service_.delay = [&](int, double x0) { return x0 == 1.0 ? 3 * period : milliseconds(0); };
  auto session = client_->OpenSession(spec_, {}, ControlPeriod{.period = period, .held_periods_to_reconnect = 10});
  ASSERT_TRUE(session.ok()) << session.status();

  const Clock::time_point start = Clock::now();
  absl::StatusOr<v1::SolveResult> held = (*session)->Step(StepAt(1.0));
  const milliseconds took = std::chrono::duration_cast<milliseconds>(Clock::now() - start);
  ASSERT_TRUE(held.ok()) << held.status();
  EXPECT_EQ(held->status(), v1::SOLVE_STATUS_HELD);
  EXPECT_FALSE(HasPlan(*held));
  EXPECT_EQ(held->inputs_size(), 0);
  EXPECT_GE(took, period - milliseconds(5));
  EXPECT_LE(took, period + kSlack);

  // Wait until the late answer has surely arrived, then step again: the result is step 2's.
  std::this_thread::sleep_for(4 * period);
  absl::StatusOr<v1::SolveResult> next = (*session)->Step(StepAt(2.0));
  ASSERT_TRUE(next.ok()) << next.status();
  ASSERT_EQ(next->status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_EQ(next->objective(), 2.0) << "an answer of an earlier step was returned for this one";
  EXPECT_EQ((*session)->late_answers(), 1);
  EXPECT_EQ((*session)->held_steps(), 1);
  EXPECT_EQ((*session)->consecutive_held_steps(), 0);
  EXPECT_EQ((*session)->reconnects(), 0);
}

TEST_F(ControlPeriodTest, KHeldPeriodsInARowRecreateTheSessionFromTheSpecTheAnswersLeft) {
  const milliseconds period(50);
  constexpr int kHeld = 3;
  // The first stream answers state 1 late (after the step was held) and then nothing; the
  // stream the session re-creates answers everything.
  service_.delay = [&](int attach, double x0) {
    if (attach > 1) return milliseconds(0);
    return x0 == 1.0 ? 2 * period : milliseconds(-1);
  };
  auto session = client_->OpenSession(spec_, {}, ControlPeriod{.period = period, .held_periods_to_reconnect = kHeld});
  ASSERT_TRUE(session.ok()) << session.status();
  const std::string first_id = (*session)->id();

  // Held steps until the stream counts as broken and a new one is up: each returns by its
  // period, and the loop keeps stepping as a controller would.
  int held = 0;
  double x0 = 1.0;
  absl::StatusOr<v1::SolveResult> result;
  for (; held < 100; ++held, x0 += 1.0) {
    const Clock::time_point start = Clock::now();
    result = (*session)->Step(StepAt(x0));
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_LE(Clock::now() - start, period + kSlack) << "step " << held;
    if (result->status() != v1::SOLVE_STATUS_HELD) break;
  }
  EXPECT_GE(held, kHeld) << "answered before the stream could have been re-created";
  EXPECT_EQ(result->objective(), x0) << "the first answer after the reconnect is not for its own step";
  EXPECT_EQ((*session)->reconnects(), 1);
  ASSERT_EQ(service_.attaches(), 2);
  // The session was asked for by its id first; this server does not hand it back, so it
  // was re-created.
  const std::vector<ScriptedControl::Attach> log = service_.attach_log();
  ASSERT_EQ(log.size(), 3u);
  EXPECT_EQ(log[1].session_id, first_id);
  EXPECT_FALSE(log[1].accepted);
  EXPECT_NE((*session)->id(), first_id);
  EXPECT_EQ((*session)->reconnect_stats().recreated, 1);
  EXPECT_EQ((*session)->reconnect_stats().reattached, 0);
  // State 1's answer came late on the first stream: the server had applied it, so the
  // session was re-created from it; the later steps were never answered, so not from them.
  EXPECT_EQ(service_.attach_spec(1).initial_state().mean(0), 1.0);
  // At least that one: on a slow machine the new stream's first answer may come late too.
  EXPECT_GE((*session)->late_answers(), 1);
}

// The server answers SUPERSEDED for a newer step at once, while an older one is still being
// solved: that answer overtakes the older step's result, which must still reach the spec.
TEST_F(ControlPeriodTest, ASupersededAnswerAheadOfAnEarlierResultLeavesThatResultInTheSpec) {
  // Long enough that state 1's answer (3 periods) comes two periods before the K rule
  // breaks the stream even on a loaded machine under TSan.
  const milliseconds period(150);
  // On the first stream: state 1 solved after 3 periods, state 2 superseded after 1.1
  // periods (both after their own step was held), nothing else. The second answers all.
  service_.superseded = [](int attach, double x0) { return attach == 1 && x0 == 2.0; };
  service_.delay = [&](int attach, double x0) {
    if (attach > 1) return milliseconds(0);
    if (x0 == 1.0) return 3 * period;
    if (x0 == 2.0) return period + period / 10;
    return milliseconds(-1);
  };
  auto session = client_->OpenSession(spec_, {}, ControlPeriod{.period = period, .held_periods_to_reconnect = 3});
  ASSERT_TRUE(session.ok()) << session.status();
  absl::StatusOr<v1::SolveResult> result;
  double x0 = 1.0;
  for (int step = 0; step < 100; ++step, x0 += 1.0) {
    result = (*session)->Step(StepAt(x0));
    ASSERT_TRUE(result.ok()) << result.status();
    if (result->status() != v1::SOLVE_STATUS_HELD) break;
  }
  EXPECT_EQ(result->objective(), x0);
  ASSERT_EQ(service_.attaches(), 2);
  EXPECT_EQ(service_.attach_spec(1).initial_state().mean(0), 1.0)
      << "state 1's result, which came after state 2's SUPERSEDED, was not applied to the spec";
  // At least those two: on a slow machine the new stream's first answer may come late too.
  EXPECT_GE((*session)->late_answers(), 2);
}

// A server that answers every step, only later than the period: every step is held, the
// late answers show the stream is alive, and it is kept (re-creating the session would
// only lose the warm start and add work to a server that is already behind).
TEST_F(ControlPeriodTest, AServerSlowerThanThePeriodKeepsItsStream) {
  const milliseconds period(40);
  service_.delay = [&](int, double) { return period + period / 2; };
  auto session = client_->OpenSession(spec_, {}, ControlPeriod{.period = period, .held_periods_to_reconnect = 3});
  ASSERT_TRUE(session.ok()) << session.status();
  for (int step = 1; step <= 12; ++step) {
    absl::StatusOr<v1::SolveResult> result = (*session)->Step(StepAt(step));
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_EQ(result->status(), v1::SOLVE_STATUS_HELD) << "step " << step;
  }
  EXPECT_EQ((*session)->reconnects(), 0);
  EXPECT_EQ(service_.attaches(), 1);
  EXPECT_GE((*session)->late_answers(), 8);
}

TEST_F(ControlPeriodTest, AClosedSessionRefusesSteps) {
  auto session = client_->OpenSession(spec_, {}, ControlPeriod{.period = milliseconds(50)});
  ASSERT_TRUE(session.ok()) << session.status();
  EXPECT_TRUE((*session)->Close().ok());
  absl::StatusOr<v1::SolveResult> result = (*session)->Step(StepAt(1.0));
  EXPECT_EQ(result.status().code(), absl::StatusCode::kFailedPrecondition);
}

TEST_F(ControlPeriodTest, WithoutAPeriodAStepWaitsForItsAnswer) {
  const milliseconds delay(300);
  service_.delay = [&](int, double) { return delay; };
  auto session = client_->OpenSession(spec_);
  ASSERT_TRUE(session.ok()) << session.status();
  const Clock::time_point start = Clock::now();
  absl::StatusOr<v1::SolveResult> result = (*session)->Step(StepAt(7.0));
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_GE(Clock::now() - start, delay - milliseconds(5));
  EXPECT_EQ(result->status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_EQ(result->objective(), 7.0);
  EXPECT_EQ((*session)->held_steps(), 0);
}

TEST_F(ControlPeriodTest, HeldPeriodsToReconnectIsAtLeastThreeAndCoversASecond) {
  EXPECT_EQ(ControlPeriod{.period = milliseconds(10)}.HeldPeriodsToReconnect(), 100);
  EXPECT_EQ(ControlPeriod{.period = milliseconds(50)}.HeldPeriodsToReconnect(), 20);
  EXPECT_EQ(ControlPeriod{.period = milliseconds(300)}.HeldPeriodsToReconnect(), 4);
  EXPECT_EQ(ControlPeriod{.period = milliseconds(1000)}.HeldPeriodsToReconnect(), 3);
  EXPECT_EQ(ControlPeriod{.period = milliseconds(5000)}.HeldPeriodsToReconnect(), 3);
  EXPECT_EQ((ControlPeriod{.period = milliseconds(50), .held_periods_to_reconnect = 7}.HeldPeriodsToReconnect()), 7);
}

}  // namespace
}  // namespace nupmpc
