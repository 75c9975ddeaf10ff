// SolveFleet (many sessions stepped in one call): each step is answered as Solve would
// answer it, one step's error fails no other, a session's steps are applied in order, and a
// step overtaken by a newer one of its session is answered SUPERSEDED with nothing applied.
// Bursts for one busy session: fleet steps end with the newest solved, unary Solve calls
// are all solved in order up to the wait bound and only the excess is refused.
#include <future>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "absl/cleanup/cleanup.h"
#include "gmock/gmock.h"
#include "server/scheduling/session_strand.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;

class FleetTest : public ServiceTest {
 protected:
  void SetUp() override {
    ServiceTest::SetUp();
    inst_ = LoadInstanceOrDie("masses_N30");
    spec_ = SpecOrDie(inst_.problem);
  }

  std::string NewSession() {
    absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(spec_);
    EXPECT_TRUE(created.ok()) << created.status();
    return created.ok() ? created->session_id() : "";
  }
  // The closed loop's recorded state number t (every session its own offset into them).
  v1::Step StateStep(std::size_t t) const {
    const Eigen::VectorXd& x = inst_.closed_loop->x1[t % inst_.closed_loop->x1.size()];
    v1::Step step;
    step.mutable_state()->Add(x.data(), x.data() + x.size());
    return step;
  }
  static v1::SolveRequest FleetStep(const std::string& session_id, const v1::Step& step) {
    v1::SolveRequest r;
    r.set_session_id(session_id);
    *r.mutable_step() = step;
    return r;
  }
  // The plan a new session gives for `steps` solved one after another with Solve.
  std::vector<double> ReferencePlan(const std::vector<v1::Step>& steps) {
    const std::string id = NewSession();
    absl::StatusOr<v1::SolveResult> r;
    for (const v1::Step& step : steps) {
      r = client_->Solve(id, step);
      EXPECT_TRUE(r.ok()) << r.status();
      if (!r.ok()) return {};
    }
    EXPECT_TRUE(client_->CloseSession(id).ok());
    return {r->inputs().begin(), r->inputs().end()};
  }
  static std::vector<double> Plan(const v1::FleetAnswer& a) {
    return {a.result().inputs().begin(), a.result().inputs().end()};
  }

  // Holds `id`'s strand, as a long solve of the session would, until ReleaseSession. A test
  // releases it at its end in any case (an absl::Cleanup declared after its calls'
  // futures, whose destructors wait for the calls): a failed assertion must not leave the
  // calls waiting for the session.
  void HoldSession(const std::string& id) {
    std::shared_future<void> released = release_.get_future().share();
    absl::StatusOr<std::shared_ptr<server::SessionEntry>> entry = server_->state().registry.Find(id);
    ASSERT_TRUE(entry.ok()) << entry.status();
    held_ = *entry;
    ASSERT_TRUE(server::SessionStrand::Submit(held_->strand, server_->state().pool,
                                              {[released] { released.wait(); }, [](absl::Status) {}, 0.0})
                    .ok());
  }
  void ReleaseSession() {
    if (!released_) release_.set_value();
    released_ = true;
  }
  auto ReleaseAtExit() {
    return absl::Cleanup([this] { ReleaseSession(); });
  }
  // Waits until `n` tasks wait for the held session.
  void WaitForQueued(int n) {
    ASSERT_NE(held_, nullptr);
    for (int i = 0; i < 3000 && held_->strand->waiting() != n; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    ASSERT_EQ(held_->strand->waiting(), n);
  }
  auto FleetAsync(v1::SolveFleetRequest request) {
    return std::async(std::launch::async, [this, request] { return client_->SolveFleet(request); });
  }

  std::shared_ptr<server::SessionEntry> held_;
  std::promise<void> release_;
  bool released_ = false;

  bench::BenchmarkInstance inst_;
  v1::ProblemSpec spec_;
};

TEST_F(FleetTest, EveryStepIsAnsweredAsSeparateSolvesAnswerIt) {
  constexpr int kSessions = 6, kPeriods = 4;
  std::vector<std::string> fleet, separate;
  for (int s = 0; s < kSessions; ++s) {
    fleet.push_back(NewSession());
    separate.push_back(NewSession());
  }
  for (int t = 0; t < kPeriods; ++t) {
    SCOPED_TRACE(t);
    v1::SolveFleetRequest request;
    for (int s = 0; s < kSessions; ++s) *request.add_steps() = FleetStep(fleet[s], StateStep(10 * s + t));
    absl::StatusOr<v1::SolveFleetResponse> answered = client_->SolveFleet(request);
    ASSERT_TRUE(answered.ok()) << answered.status();
    ASSERT_EQ(answered->answers_size(), kSessions);
    for (int s = 0; s < kSessions; ++s) {
      const v1::FleetAnswer& a = answered->answers(s);
      EXPECT_EQ(a.session_id(), fleet[s]);
      EXPECT_EQ(a.error_code(), 0) << a.error_message();
      EXPECT_EQ(a.result().status(), v1::SOLVE_STATUS_CONVERGED);
      absl::StatusOr<v1::SolveResult> alone = client_->Solve(separate[s], StateStep(10 * s + t));
      ASSERT_TRUE(alone.ok()) << alone.status();
      EXPECT_EQ(a.result().warm_started(), alone->warm_started());
      EXPECT_EQ(Plan(a), std::vector<double>(alone->inputs().begin(), alone->inputs().end())) << "session " << s;
    }
  }
}

TEST_F(FleetTest, OneStepsErrorFailsNoOtherAndLeavesItsSessionAsItWas) {
  const std::string good = NewSession(), bad = NewSession(), closed = NewSession(), attached_spec_owner = NewSession();
  ASSERT_TRUE(client_->CloseSession(closed).ok());
  absl::StatusOr<std::unique_ptr<Session>> streamed = client_->OpenSession(spec_);
  ASSERT_TRUE(streamed.ok()) << streamed.status();
  const std::string attached = (*streamed)->id();

  v1::Step not_finite = StateStep(1);
  not_finite.set_state(0, std::numeric_limits<double>::quiet_NaN());
  v1::SolveFleetRequest request;
  *request.add_steps() = FleetStep(good, StateStep(0));
  *request.add_steps() = FleetStep("0123456789abcdef0123456789abcdef", StateStep(0));
  *request.add_steps() = FleetStep(bad, not_finite);
  *request.add_steps() = FleetStep(closed, StateStep(0));
  *request.add_steps() = FleetStep(attached, StateStep(0));
  *request.add_steps() = FleetStep(attached_spec_owner, StateStep(2));
  absl::StatusOr<v1::SolveFleetResponse> answered = client_->SolveFleet(request);
  ASSERT_TRUE(answered.ok()) << answered.status();
  ASSERT_EQ(answered->answers_size(), 6);
  const auto& a = answered->answers();
  EXPECT_EQ(a[0].result().status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_EQ(a[1].error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_THAT(a[1].error_message(), HasSubstr("steps[1].session_id"));
  EXPECT_FALSE(a[1].has_result());
  EXPECT_EQ(a[2].error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(a[2].error_message(), HasSubstr("steps[2]."));
  EXPECT_THAT(a[2].error_message(), HasSubstr("state[0]"));
  EXPECT_FALSE(a[2].has_result());
  EXPECT_EQ(a[3].error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(a[4].error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_THAT(a[4].error_message(), HasSubstr("Control stream"));
  EXPECT_EQ(a[5].result().status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_EQ(Plan(a[0]), ReferencePlan({StateStep(0)}));
  EXPECT_EQ(Plan(a[5]), ReferencePlan({StateStep(2)}));

  // The rejected step changed nothing: the session's next step is its first.
  absl::StatusOr<v1::SolveResult> after = client_->Solve(bad, StateStep(3));
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_EQ(std::vector<double>(after->inputs().begin(), after->inputs().end()), ReferencePlan({StateStep(3)}));
}

TEST_F(FleetTest, ASessionTwiceInOneCallSolvesOnlyItsLastStep) {
  const std::string id = NewSession();
  v1::SolveFleetRequest request;
  *request.add_steps() = FleetStep(id, StateStep(5));
  *request.add_steps() = FleetStep(id, StateStep(9));
  absl::StatusOr<v1::SolveFleetResponse> answered = client_->SolveFleet(request);
  ASSERT_TRUE(answered.ok()) << answered.status();
  ASSERT_EQ(answered->answers_size(), 2);
  EXPECT_EQ(answered->answers(0).result().status(), v1::SOLVE_STATUS_SUPERSEDED);
  EXPECT_FALSE(answered->answers(0).result().has_plan());
  EXPECT_EQ(answered->answers(1).result().status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_EQ(Plan(answered->answers(1)), ReferencePlan({StateStep(9)}));  // step 5 was never applied
}

TEST_F(FleetTest, AStepOvertakenByALaterCallIsSupersededAndLaterStepsFollowInOrder) {
  const std::string busy = NewSession(), free = NewSession();
  std::future<absl::StatusOr<v1::SolveFleetResponse>> first_answer, second_answer;
  const auto release_at_exit = ReleaseAtExit();
  HoldSession(busy);
  v1::SolveFleetRequest first;
  *first.add_steps() = FleetStep(busy, StateStep(3));
  *first.add_steps() = FleetStep(free, StateStep(4));
  first_answer = FleetAsync(first);
  WaitForQueued(1);
  v1::SolveFleetRequest second;
  *second.add_steps() = FleetStep(busy, StateStep(7));
  second_answer = FleetAsync(second);
  // The overtaken step gives up its place at once: the first call is answered while the
  // session is still busy, and only the newest step waits.
  ASSERT_EQ(first_answer.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  WaitForQueued(1);
  ReleaseSession();

  absl::StatusOr<v1::SolveFleetResponse> a = first_answer.get(), b = second_answer.get();
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(a->answers(0).result().status(), v1::SOLVE_STATUS_SUPERSEDED);
  EXPECT_EQ(a->answers(1).result().status(), v1::SOLVE_STATUS_CONVERGED);  // the other session did not wait for it
  EXPECT_EQ(b->answers(0).result().status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_EQ(Plan(b->answers(0)), ReferencePlan({StateStep(7)}));

  // A later call's step follows the one before it: the session has seen 7, then 8.
  v1::SolveFleetRequest third;
  *third.add_steps() = FleetStep(busy, StateStep(8));
  absl::StatusOr<v1::SolveFleetResponse> c = client_->SolveFleet(third);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(Plan(c->answers(0)), ReferencePlan({StateStep(7), StateStep(8)}));
}

// More entries for one busy session than may wait for it, in one call: all but the last
// are superseded without waiting, the last is solved.
TEST_F(FleetTest, ABurstInOneCallForABusySessionEndsWithItsNewestStepSolved) {
  const std::string id = NewSession();
  constexpr int kBurst = server::SessionStrand::kMaxWaiting + 4;
  std::future<absl::StatusOr<v1::SolveFleetResponse>> answer;
  const auto release_at_exit = ReleaseAtExit();
  HoldSession(id);
  v1::SolveFleetRequest burst;
  for (int t = 0; t < kBurst; ++t) *burst.add_steps() = FleetStep(id, StateStep(t));
  answer = FleetAsync(burst);
  WaitForQueued(1);
  ReleaseSession();
  absl::StatusOr<v1::SolveFleetResponse> answered = answer.get();
  ASSERT_TRUE(answered.ok()) << answered.status();
  ASSERT_EQ(answered->answers_size(), kBurst);
  for (int t = 0; t + 1 < kBurst; ++t) {
    EXPECT_EQ(answered->answers(t).error_code(), 0) << t << ": " << answered->answers(t).error_message();
    EXPECT_EQ(answered->answers(t).result().status(), v1::SOLVE_STATUS_SUPERSEDED) << t;
  }
  const v1::FleetAnswer& newest = answered->answers(kBurst - 1);
  ASSERT_EQ(newest.error_code(), 0) << newest.error_message();
  EXPECT_EQ(newest.result().status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_EQ(Plan(newest), ReferencePlan({StateStep(kBurst - 1)}));
}

// The same burst as one call per step, each sent once the one before waits: every older
// step is superseded as the next arrives (its call answered while the session is busy),
// none is refused, and the newest is solved.
TEST_F(FleetTest, ABurstOfCallsForABusySessionEndsWithItsNewestStepSolved) {
  const std::string id = NewSession();
  constexpr int kBurst = server::SessionStrand::kMaxWaiting + 4;
  std::vector<std::future<absl::StatusOr<v1::SolveFleetResponse>>> answers;
  const auto release_at_exit = ReleaseAtExit();
  HoldSession(id);
  for (int t = 0; t < kBurst; ++t) {
    v1::SolveFleetRequest one;
    *one.add_steps() = FleetStep(id, StateStep(t));
    answers.push_back(FleetAsync(one));
    if (t > 0) {
      ASSERT_EQ(answers[t - 1].wait_for(std::chrono::seconds(10)), std::future_status::ready) << t;
    }
    WaitForQueued(1);
  }
  ReleaseSession();
  for (int t = 0; t < kBurst; ++t) {
    absl::StatusOr<v1::SolveFleetResponse> a = answers[t].get();
    ASSERT_TRUE(a.ok()) << t << ": " << a.status();
    ASSERT_EQ(a->answers(0).error_code(), 0) << t << ": " << a->answers(0).error_message();
    EXPECT_EQ(a->answers(0).result().status(),
              t + 1 < kBurst ? v1::SOLVE_STATUS_SUPERSEDED : v1::SOLVE_STATUS_CONVERGED)
        << t;
  }
}

// Unary Solve calls of one busy session are never superseded: those that may wait are all
// solved, in order, and only the excess is refused (proto: SolveRequest).
TEST_F(FleetTest, AUnaryBurstForABusySessionIsSolvedInOrderAndOnlyTheExcessRefused) {
  const std::string id = NewSession();
  constexpr int kWaiting = server::SessionStrand::kMaxWaiting;
  std::vector<std::future<absl::StatusOr<v1::SolveResult>>> answers;
  const auto release_at_exit = ReleaseAtExit();
  HoldSession(id);
  std::vector<v1::Step> sent;
  for (int t = 0; t < kWaiting + 4; ++t) {
    sent.push_back(StateStep(t));
    answers.push_back(
        std::async(std::launch::async, [this, id, step = sent.back()] { return client_->Solve(id, step); }));
    if (t < kWaiting) {
      WaitForQueued(t + 1);
    } else {
      absl::StatusOr<v1::SolveResult> refused = answers.back().get();
      ASSERT_FALSE(refused.ok()) << t;
      EXPECT_EQ(refused.status().code(), absl::StatusCode::kResourceExhausted) << t;
      EXPECT_THAT(std::string(refused.status().message()), HasSubstr("solves already wait for this session"));
    }
  }
  ReleaseSession();
  std::vector<double> last;
  for (int t = 0; t < kWaiting; ++t) {
    absl::StatusOr<v1::SolveResult> r = answers[t].get();
    ASSERT_TRUE(r.ok()) << t << ": " << r.status();
    EXPECT_EQ(r->status(), v1::SOLVE_STATUS_CONVERGED) << t;
    EXPECT_TRUE(r->has_plan()) << t;
    last.assign(r->inputs().begin(), r->inputs().end());
  }
  // In order: the session saw the waiting states one after another, none of the refused.
  EXPECT_EQ(last, ReferencePlan(std::vector<v1::Step>(sent.begin(), sent.begin() + kWaiting)));
}

TEST_F(FleetTest, ACallOverTheStepLimitIsRefusedNamingIt) {
  TearDown();
  server::ServerOptions options = DefaultOptions();
  options.max_fleet_steps = 3;
  StartServer(options);
  const std::string id = NewSession();
  v1::SolveFleetRequest request;
  for (int i = 0; i < 4; ++i) *request.add_steps() = FleetStep(id, StateStep(i));
  absl::StatusOr<v1::SolveFleetResponse> refused = client_->SolveFleet(request);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(refused.status().message()), HasSubstr("max_fleet_steps"));
  request.mutable_steps()->RemoveLast();
  EXPECT_TRUE(client_->SolveFleet(request).ok());
  v1::SolveFleetRequest empty;
  absl::StatusOr<v1::SolveFleetResponse> none = client_->SolveFleet(empty);
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_EQ(none->answers_size(), 0);
}

}  // namespace
}  // namespace nupmpc::testing
