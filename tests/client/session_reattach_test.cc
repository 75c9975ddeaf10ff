// How a nupmpc::Session gets its session back when its Control stream breaks, against a
// scripted Control service (tests/client/scripted_control.h) that plays a server which
// kept (or restored) the session, or one that does not have it: the session is asked for
// by its id first, on a stream routed by that id; a server that hands it back keeps it
// (re-attached, same id) and gets the unanswered step exactly once; NOT_FOUND or
// FAILED_PRECONDITION re-create it from the spec; UNAVAILABLE is retried with back-off.
// Every step's result is its own (the scripted answer's objective is the step's state).
#include <chrono>
#include <string>
#include <vector>

#include "client/client.h"
#include "gtest/gtest.h"
#include "tests/client/scripted_control.h"

namespace nupmpc {
namespace {

using std::chrono::milliseconds;
using testing::ScriptedControl;

class SessionReattachTest : public ::testing::Test {
 protected:
  void SetUp() override {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(&service_);
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    client_ = std::make_unique<Client>("127.0.0.1:" + std::to_string(port_));
    spec_.mutable_initial_state()->add_mean(0.0);
    // The first stream goes away with state 2 unanswered; later streams answer everything.
    service_.breaks = [](int attach, double x0) { return attach == 1 && x0 == 2.0; };
    reconnect_.initial_backoff = milliseconds(10);
    reconnect_.budget = milliseconds(20000);
    reconnect_.on_attempt = [this](const ReconnectAttempt& a) { attempts_.push_back(a); };
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
  // How often the service received state x0 on the stream numbered `attach` (0: any).
  int Received(double x0, int attach = 0) const {
    int n = 0;
    for (const ScriptedControl::Received& r : service_.received()) {
      n += r.x0 == x0 && (attach == 0 || r.attach == attach) ? 1 : 0;
    }
    return n;
  }
  // Steps 1 (answered) and 2 (its stream breaks): returns step 2's result.
  absl::StatusOr<v1::SolveResult> StepThroughTheBreak(Session& session) {
    absl::StatusOr<v1::SolveResult> first = session.Step(StepAt(1.0));
    EXPECT_TRUE(first.ok()) << first.status();
    if (first.ok()) {
      EXPECT_EQ(first->objective(), 1.0);
    }
    return session.Step(StepAt(2.0));
  }

  ScriptedControl service_;
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<Client> client_;
  v1::ProblemSpec spec_;
  ReconnectOptions reconnect_;
  std::vector<ReconnectAttempt> attempts_;
};

TEST_F(SessionReattachTest, AServerThatKeptTheSessionGetsItBackByIdAndTheUnansweredStepOnce) {
  service_.attach_by_id = [](const std::string&) { return grpc::Status::OK; };
  auto session = client_->OpenSession(spec_, reconnect_);
  ASSERT_TRUE(session.ok()) << session.status();
  const std::string id = (*session)->id();
  ASSERT_EQ(id.size(), 32u);

  absl::StatusOr<v1::SolveResult> result = StepThroughTheBreak(**session);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->objective(), 2.0) << "the result is not the resent step's own";
  EXPECT_EQ((*session)->id(), id) << "a re-attached session keeps its id";
  const ReconnectStats stats = (*session)->reconnect_stats();
  EXPECT_EQ(stats.reconnects, 1);
  EXPECT_EQ(stats.reattached, 1);
  EXPECT_EQ(stats.recreated, 0);
  EXPECT_EQ(service_.attaches(), 1) << "nothing was re-created";

  // The attach named the session and carried the routing header a balancer hashes.
  const std::vector<ScriptedControl::Attach> log = service_.attach_log();
  ASSERT_EQ(log.size(), 2u);
  EXPECT_EQ(log[1].session_id, id);
  EXPECT_EQ(log[1].routing_header, id);
  EXPECT_TRUE(log[1].accepted);
  // A stream that creates its session is routed anywhere: no header.
  EXPECT_EQ(log[0].routing_header, "");

  // State 2 reached the first stream (which broke) and the re-attached one exactly once.
  EXPECT_EQ(Received(2.0, /*attach=*/1), 1);
  EXPECT_EQ(Received(2.0, /*attach=*/2), 1);
  ASSERT_EQ(attempts_.size(), 1u);
  EXPECT_EQ(attempts_[0].path, ReconnectPath::kReattached);
  ASSERT_TRUE(attempts_[0].attach_by_id.has_value());
  EXPECT_TRUE(attempts_[0].attach_by_id->ok());

  // The session goes on on the re-attached stream.
  absl::StatusOr<v1::SolveResult> next = (*session)->Step(StepAt(3.0));
  ASSERT_TRUE(next.ok()) << next.status();
  EXPECT_EQ(next->objective(), 3.0);
  EXPECT_EQ(Received(3.0, /*attach=*/2), 1);
  EXPECT_EQ(Received(1.0), 1);
}

// NOT_FOUND (no snapshot, or the window passed) and FAILED_PRECONDITION (another stream
// holds it): the old behaviour, the session re-created from the spec under a new id.
TEST_F(SessionReattachTest, ASessionTheServerDoesNotHandBackIsRecreatedFromTheSpec) {
  for (const grpc::StatusCode code : {grpc::StatusCode::NOT_FOUND, grpc::StatusCode::FAILED_PRECONDITION}) {
    SCOPED_TRACE(code);
    attempts_.clear();
    const std::size_t logged = service_.attach_log().size();
    service_.attach_by_id = [code](const std::string&) { return grpc::Status(code, "not here"); };
    // Each round has two sessions (created, re-created): the first one's stream breaks.
    service_.breaks = [](int attach, double x0) { return x0 == 2.0 && attach % 2 == 1; };
    auto session = client_->OpenSession(spec_, reconnect_);
    ASSERT_TRUE(session.ok()) << session.status();
    const std::string id = (*session)->id();

    absl::StatusOr<v1::SolveResult> result = StepThroughTheBreak(**session);
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_EQ(result->objective(), 2.0);
    EXPECT_NE((*session)->id(), id);
    const ReconnectStats stats = (*session)->reconnect_stats();
    EXPECT_EQ(stats.reconnects, 1);
    EXPECT_EQ(stats.reattached, 0);
    EXPECT_EQ(stats.recreated, 1);
    EXPECT_EQ(stats.attempts, 1) << "the re-creation is part of the attempt whose attach missed";

    // In order: the session created, asked for by its id (refused), created again from
    // the spec the answered step 1 left.
    const std::vector<ScriptedControl::Attach> log = service_.attach_log();
    ASSERT_EQ(log.size(), logged + 3);
    EXPECT_EQ(log[logged + 1].session_id, id);
    EXPECT_FALSE(log[logged + 1].accepted);
    EXPECT_EQ(log[logged + 2].session_id, "");
    EXPECT_EQ(log[logged + 2].spec.initial_state().mean(0), 1.0);
    ASSERT_EQ(attempts_.size(), 1u);
    EXPECT_EQ(attempts_[0].path, ReconnectPath::kRecreated);
    ASSERT_TRUE(attempts_[0].attach_by_id.has_value());
    EXPECT_EQ(static_cast<int>(attempts_[0].attach_by_id->code()), static_cast<int>(code));
    ASSERT_TRUE((*session)->Close().ok());
  }
}

// A server that is not there yet (UNAVAILABLE) is waited for: the back-off retries the
// attach by id, and the session comes back warm when the server does.
TEST_F(SessionReattachTest, AnUnavailableAttachIsRetriedByIdNotRecreated) {
  int asked = 0;
  service_.attach_by_id = [&asked](const std::string&) {
    return ++asked < 3 ? grpc::Status(grpc::StatusCode::UNAVAILABLE, "restoring") : grpc::Status::OK;
  };
  auto session = client_->OpenSession(spec_, reconnect_);
  ASSERT_TRUE(session.ok()) << session.status();
  const std::string id = (*session)->id();
  absl::StatusOr<v1::SolveResult> result = StepThroughTheBreak(**session);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->objective(), 2.0);
  EXPECT_EQ((*session)->id(), id);
  const ReconnectStats stats = (*session)->reconnect_stats();
  EXPECT_EQ(stats.attempts, 3);
  EXPECT_EQ(stats.reattached, 1);
  EXPECT_EQ(stats.recreated, 0);
  EXPECT_EQ(service_.attaches(), 1);
  ASSERT_EQ(attempts_.size(), 3u);
  EXPECT_TRUE(absl::IsUnavailable(attempts_[0].result));
  EXPECT_EQ(attempts_[0].path, ReconnectPath::kNone);
  EXPECT_EQ(attempts_[2].path, ReconnectPath::kReattached);
  // Only the attempt that got the session back resent the step.
  EXPECT_EQ(Received(2.0), 2);
}

// With a control period the background reconnect does the same: K held periods break the
// stream, and the session comes back by its id.
TEST_F(SessionReattachTest, WithAPeriodTheBackgroundReconnectReattachesByIdToo) {
  const milliseconds period(50);
  service_.breaks = [](int, double) { return false; };
  // The first stream answers state 1 and then nothing; the re-attached one everything.
  service_.delay = [](int attach, double x0) { return attach > 1 || x0 == 1.0 ? milliseconds(0) : milliseconds(-1); };
  service_.attach_by_id = [](const std::string&) { return grpc::Status::OK; };
  auto session =
      client_->OpenSession(spec_, reconnect_, ControlPeriod{.period = period, .held_periods_to_reconnect = 3});
  ASSERT_TRUE(session.ok()) << session.status();
  const std::string id = (*session)->id();
  absl::StatusOr<v1::SolveResult> result;
  double x0 = 1.0;
  for (int step = 0; step < 200; ++step, x0 += 1.0) {
    result = (*session)->Step(StepAt(x0));
    ASSERT_TRUE(result.ok()) << result.status();
    // State 1's answer (at once, or late on a slow machine) is not the one looked for.
    if (result->status() != v1::SOLVE_STATUS_HELD && x0 > 1.0) break;
  }
  ASSERT_EQ(result->status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_EQ(result->objective(), x0) << "the first answer after the reconnect is not for its own step";
  EXPECT_EQ((*session)->id(), id);
  const ReconnectStats stats = (*session)->reconnect_stats();
  EXPECT_EQ(stats.reconnects, 1);
  EXPECT_EQ(stats.reattached, 1);
  EXPECT_EQ(stats.recreated, 0);
  EXPECT_EQ(service_.attaches(), 1);
}

}  // namespace
}  // namespace nupmpc
