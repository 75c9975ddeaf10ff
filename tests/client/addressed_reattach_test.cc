// How an AddressedSession gets its session back after a Solve failed, against a scripted
// service on a real gRPC server in this process: after UNAVAILABLE (a replica restarting or
// draining) the step is resent to the same id first, which a server that restored the
// session from its snapshot answers warm (re-attached, same id); a server that answers
// NOT_FOUND for it has neither the session nor a snapshot, and the session is re-created
// under a new id. Every result is its own step's (the scripted objective is the state).
#include <chrono>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "client/addressed_session.h"
#include "gtest/gtest.h"

namespace nupmpc {
namespace {

using std::chrono::milliseconds;

// CreateSession keeps the id the client drew; Solve answers UNAVAILABLE for its next
// `failing` calls, NOT_FOUND for an id it does not hold, else a result whose objective is
// the step's state[0].
class ScriptedSolve final : public v1::MpcService::CallbackService {
 public:
  void FailNext(int calls) {
    std::lock_guard<std::mutex> lock(mu_);
    failing_ = calls;
  }
  void Forget(const std::string& id) {
    std::lock_guard<std::mutex> lock(mu_);
    sessions_.erase(id);
  }
  std::vector<std::string> created() const {
    std::lock_guard<std::mutex> lock(mu_);
    return created_;
  }
  std::vector<std::string> solved_ids() const {  // the id of every Solve call, in order
    std::lock_guard<std::mutex> lock(mu_);
    return solved_ids_;
  }

  grpc::ServerUnaryReactor* CreateSession(grpc::CallbackServerContext* context, const v1::CreateSessionRequest* request,
                                          v1::CreateSessionResponse* response) override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      created_.push_back(request->session_id());
      sessions_.insert(request->session_id());
    }
    response->set_session_id(request->session_id());
    return Done(context, grpc::Status::OK);
  }
  grpc::ServerUnaryReactor* Solve(grpc::CallbackServerContext* context, const v1::SolveRequest* request,
                                  v1::SolveResponse* response) override {
    std::lock_guard<std::mutex> lock(mu_);
    solved_ids_.push_back(request->session_id());
    if (failing_ > 0) {
      --failing_;
      return Done(context, grpc::Status(grpc::StatusCode::UNAVAILABLE, "the scripted replica is restarting"));
    }
    if (sessions_.count(request->session_id()) == 0) {
      return Done(context, grpc::Status(grpc::StatusCode::NOT_FOUND, "session_id: no such session"));
    }
    response->mutable_result()->set_status(v1::SOLVE_STATUS_CONVERGED);
    response->mutable_result()->set_has_plan(true);
    response->mutable_result()->set_objective(request->step().state(0));
    return Done(context, grpc::Status::OK);
  }
  grpc::ServerUnaryReactor* CloseSession(grpc::CallbackServerContext* context, const v1::CloseSessionRequest* request,
                                         v1::CloseSessionResponse* /*response*/) override {
    std::lock_guard<std::mutex> lock(mu_);
    sessions_.erase(request->session_id());
    return Done(context, grpc::Status::OK);
  }

 private:
  static grpc::ServerUnaryReactor* Done(grpc::CallbackServerContext* context, const grpc::Status& status) {
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    reactor->Finish(status);
    return reactor;
  }

  mutable std::mutex mu_;
  int failing_ = 0;
  std::set<std::string> sessions_;
  std::vector<std::string> created_, solved_ids_;
};

class AddressedReattachTest : public ::testing::Test {
 protected:
  void SetUp() override {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(&service_);
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    client_ = std::make_unique<Client>("127.0.0.1:" + std::to_string(port_));
    spec_.mutable_initial_state()->add_mean(0.0);
    reconnect_.initial_backoff = milliseconds(5);
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

  ScriptedSolve service_;
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<Client> client_;
  v1::ProblemSpec spec_;
  ReconnectOptions reconnect_;
  std::vector<ReconnectAttempt> attempts_;
};

TEST_F(AddressedReattachTest, AfterUnavailableTheSameIdIsAskedAgainAndAnsweredWarm) {
  auto session = AddressedSession::Create(client_.get(), spec_, reconnect_);
  ASSERT_TRUE(session.ok()) << session.status();
  const std::string id = (*session)->id();
  ASSERT_TRUE((*session)->Step(StepAt(1.0)).ok());
  service_.FailNext(2);  // the step's own call and the first attempt's
  absl::StatusOr<v1::SolveResult> result = (*session)->Step(StepAt(2.0));
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->objective(), 2.0);
  EXPECT_EQ((*session)->id(), id);
  const ReconnectStats stats = (*session)->reconnect_stats();
  EXPECT_EQ(stats.reconnects, 1);
  EXPECT_EQ(stats.reattached, 1);
  EXPECT_EQ(stats.recreated, 0);
  EXPECT_EQ(stats.attempts, 2);
  EXPECT_EQ(service_.created(), std::vector<std::string>{id}) << "nothing was re-created";
  EXPECT_EQ(service_.solved_ids(), std::vector<std::string>(4, id));
  ASSERT_EQ(attempts_.size(), 2u);
  EXPECT_EQ(attempts_[1].path, ReconnectPath::kReattached);
}

TEST_F(AddressedReattachTest, AServerBackWithoutTheSessionGetsItRecreatedInTheSameAttempt) {
  auto session = AddressedSession::Create(client_.get(), spec_, reconnect_);
  ASSERT_TRUE(session.ok()) << session.status();
  const std::string id = (*session)->id();
  ASSERT_TRUE((*session)->Step(StepAt(1.0)).ok());
  service_.FailNext(1);
  service_.Forget(id);  // restarted without a snapshot of it
  absl::StatusOr<v1::SolveResult> result = (*session)->Step(StepAt(2.0));
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->objective(), 2.0);
  const std::string new_id = (*session)->id();
  EXPECT_NE(new_id, id);
  const ReconnectStats stats = (*session)->reconnect_stats();
  EXPECT_EQ(stats.reattached, 0);
  EXPECT_EQ(stats.recreated, 1);
  EXPECT_EQ(stats.attempts, 1);
  // The step's call (UNAVAILABLE), the same id again (NOT_FOUND), then the new session.
  EXPECT_EQ(service_.solved_ids(), (std::vector<std::string>{id, id, id, new_id}));
  ASSERT_EQ(attempts_.size(), 1u);
  ASSERT_TRUE(attempts_[0].attach_by_id.has_value());
  EXPECT_TRUE(absl::IsNotFound(*attempts_[0].attach_by_id));
}

// NOT_FOUND from the start: the id leads to a replica that has neither the session nor a
// snapshot of it; asking again by the id cannot help, so the session is re-created at once.
TEST_F(AddressedReattachTest, NotFoundAtOnceRecreatesWithoutAskingByIdAgain) {
  auto session = AddressedSession::Create(client_.get(), spec_, reconnect_);
  ASSERT_TRUE(session.ok()) << session.status();
  const std::string id = (*session)->id();
  service_.Forget(id);
  absl::StatusOr<v1::SolveResult> result = (*session)->Step(StepAt(3.0));
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->objective(), 3.0);
  EXPECT_EQ((*session)->reconnect_stats().recreated, 1);
  EXPECT_EQ(service_.solved_ids(), (std::vector<std::string>{id, (*session)->id()}));
  ASSERT_EQ(attempts_.size(), 1u);
  EXPECT_FALSE(attempts_[0].attach_by_id.has_value());
}

}  // namespace
}  // namespace nupmpc
