// Callers and ownership: bearer tokens checked before any handler runs, sessions owned by
// the principal that created them (another principal gets the NOT_FOUND an unknown id
// gets, on every call that names a session, and its ListSessions does not show them),
// admins who see and close all, per-principal quotas, a tokens file re-read on change, and
// without authentication ListSessions limited to the caller's connection.
#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "client/channel_factory.h"
#include "client/channel_security.h"
#include "client/session_routing.h"
#include "gtest/gtest.h"
#include "loadtest/transport_floor.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

constexpr char kAliceToken[] = "alice-0123456789abcdef";
constexpr char kBobToken[] = "bob-0123456789abcdef01";
constexpr char kOpsToken[] = "ops-0123456789abcdef01";

v1::Step StepFrom(const Eigen::VectorXd& x) {
  v1::Step step;
  step.mutable_state()->Add(x.data(), x.data() + x.size());
  return step;
}

class AuthTest : public ::testing::Test {
 protected:
  void SetUp() override {
    spdlog::set_level(spdlog::level::warn);
    tokens_file_ = ::testing::TempDir() + "/auth-tokens-" + std::to_string(::getpid());
    WriteTokens(absl::StrCat(kAliceToken, " alice\n", kBobToken, " bob\n", kOpsToken, " ops admin\n"));
    inst_ = LoadInstanceOrDie("masses_N30");
    spec_ = SpecOrDie(inst_.problem);
  }
  void TearDown() override {
    if (server_ != nullptr) server_->Shutdown();
    std::filesystem::remove(tokens_file_);
  }
  void WriteTokens(const std::string& text) {
    std::ofstream(tokens_file_ + ".new") << text;
    std::filesystem::rename(tokens_file_ + ".new", tokens_file_);
  }
  void Start(server::ServerOptions o = {}) {
    o.address = "127.0.0.1:0";
    o.grace_period_s = 1.0;
    o.auth_tokens_file = tokens_file_;
    absl::StatusOr<std::unique_ptr<server::GrpcServer>> s = server::GrpcServer::Start(o);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
    target_ = "127.0.0.1:" + std::to_string(server_->port());
  }
  std::unique_ptr<Client> As(const std::string& token) {
    ChannelSecurity security;
    security.token = token;
    absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(target_, security, std::chrono::seconds(10));
    EXPECT_TRUE(client.ok()) << client.status();
    return client.ok() ? *std::move(client) : nullptr;
  }

  std::string tokens_file_;
  bench::BenchmarkInstance inst_;
  v1::ProblemSpec spec_;
  std::unique_ptr<server::GrpcServer> server_;
  std::string target_;
};

TEST_F(AuthTest, CallsWithoutAValidTokenAreUnauthenticatedButHealthChecksAreAnswered) {
  Start();
  Client anonymous(target_, std::chrono::seconds(10));
  EXPECT_EQ(anonymous.GetServerInfo().status().code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(anonymous.ListSessions().status().code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(anonymous.CreateSession(spec_).status().code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(anonymous.OpenSession(spec_).status().code(), absl::StatusCode::kUnauthenticated);
  const absl::Status wrong = As("not-a-token-of-the-file")->GetServerInfo().status();
  EXPECT_EQ(wrong.code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(wrong.message().find("not-a-token"), std::string::npos) << wrong;  // never echoed
  EXPECT_EQ(server_->state().registry.size(), 0);

  EXPECT_TRUE(loadtest::MeasureTransportFloor(target_, 1).ok());  // grpc.health.v1 without a token
  EXPECT_TRUE(As(kAliceToken)->GetServerInfo().ok());
  EXPECT_GE(server_->state().auth->refused_total(), 5u);
}

TEST_F(AuthTest, AnotherPrincipalCannotSeeListAttachToSolveOnOrCloseASession) {
  Start();
  std::unique_ptr<Client> alice = As(kAliceToken);
  std::unique_ptr<Client> bob = As(kBobToken);
  auto created = alice->CreateSession(spec_);
  ASSERT_TRUE(created.ok()) << created.status();
  const std::string id = created->session_id();
  const v1::Step step = StepFrom(inst_.closed_loop->x1[0]);
  auto before = alice->Solve(id, step);
  ASSERT_TRUE(before.ok()) << before.status();

  // Bob's answers are those for an id that does not exist.
  const std::string unknown = NewSessionId();
  const auto same_as_unknown = [&](const absl::Status& got, const absl::Status& for_unknown) {
    EXPECT_EQ(got.code(), absl::StatusCode::kNotFound) << got;
    EXPECT_EQ(got.code(), for_unknown.code());
    EXPECT_EQ(got.message().substr(got.message().find(':')),
              for_unknown.message().substr(for_unknown.message().find(':')));
  };
  same_as_unknown(bob->GetSession(id).status(), bob->GetSession(unknown).status());
  same_as_unknown(bob->Solve(id, step).status(), bob->Solve(unknown, step).status());
  same_as_unknown(bob->CloseSession(id), bob->CloseSession(unknown));
  auto bob_list = bob->ListSessions();
  ASSERT_TRUE(bob_list.ok());
  EXPECT_TRUE(bob_list->empty());
  {  // attach by id on a Control stream
    grpc::ClientContext context;
    auto stream = bob->stub().Control(&context);
    v1::ControlRequest attach;
    attach.set_session_id(id);
    *attach.mutable_step() = step;
    ASSERT_TRUE(stream->Write(attach));
    stream->WritesDone();
    v1::ControlResponse ignored;
    while (stream->Read(&ignored)) {
    }
    const grpc::Status status = stream->Finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND) << status.error_message();
  }

  // Alice's session is as it was: still hers, not attached, the solve count and the plan
  // for the same state unchanged.
  auto info = alice->GetSession(id);
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->solves(), 1u);
  EXPECT_FALSE(info->attached());
  auto listed = alice->ListSessions();
  ASSERT_TRUE(listed.ok());
  ASSERT_EQ(listed->size(), 1u);
  EXPECT_EQ(listed->front().session_id(), id);
  auto after = alice->Solve(id, step);
  ASSERT_TRUE(after.ok()) << after.status();
  ASSERT_EQ(after->inputs_size(), before->inputs_size());
  for (int i = 0; i < after->inputs_size(); ++i) EXPECT_NEAR(after->inputs(i), before->inputs(i), 1e-6);
}

TEST_F(AuthTest, AnAdminSeesAndClosesEverySession) {
  Start();
  std::unique_ptr<Client> alice = As(kAliceToken);
  std::unique_ptr<Client> bob = As(kBobToken);
  ASSERT_TRUE(alice->CreateSession(spec_).ok());
  auto bobs = bob->CreateSession(spec_);
  ASSERT_TRUE(bobs.ok());
  std::unique_ptr<Client> ops = As(kOpsToken);
  auto all = ops->ListSessions();
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->size(), 2u);
  EXPECT_TRUE(ops->GetSession(bobs->session_id()).ok());
  EXPECT_TRUE(ops->CloseSession(bobs->session_id()).ok());
  EXPECT_EQ(bob->GetSession(bobs->session_id()).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(server_->state().registry.size(), 1);
}

TEST_F(AuthTest, PerPrincipalQuotasOfSessionsAndStreams) {
  server::ServerOptions o;
  o.max_sessions_per_principal = 2;
  o.max_streams_per_principal = 1;
  Start(o);
  std::unique_ptr<Client> alice = As(kAliceToken);
  std::unique_ptr<Client> bob = As(kBobToken);
  auto first = alice->CreateSession(spec_);
  ASSERT_TRUE(first.ok());
  ASSERT_TRUE(alice->CreateSession(spec_).ok());
  auto third = alice->CreateSession(spec_);
  EXPECT_EQ(third.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(third.status().message().find("max_sessions_per_principal"), std::string::npos) << third.status();
  EXPECT_TRUE(bob->CreateSession(spec_).ok());  // bob's own quota
  ASSERT_TRUE(alice->CloseSession(first->session_id()).ok());
  EXPECT_TRUE(alice->CreateSession(spec_).ok());  // the closed one's place is free again

  auto stream = bob->OpenSession(spec_);
  ASSERT_TRUE(stream.ok()) << stream.status();
  auto second_stream = bob->OpenSession(spec_);
  EXPECT_EQ(second_stream.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(second_stream.status().message().find("max_streams_per_principal"), std::string::npos)
      << second_stream.status();
  ASSERT_TRUE((*stream)->Close().ok());
  // The quota is given back when the stream is done (OnDone runs after the client's close).
  bool reopened = false;
  for (int attempt = 0; attempt < 100 && !reopened; ++attempt) {
    reopened = bob->OpenSession(spec_).ok();
    if (!reopened) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_TRUE(reopened);
}

TEST_F(AuthTest, AChangedTokensFileTakesEffectWithoutARestart) {
  Start();
  ASSERT_TRUE(As(kBobToken)->GetServerInfo().ok());
  const std::string carol_token = "carol-0123456789abcdef";
  WriteTokens(absl::StrCat(kAliceToken, " alice\n", carol_token, " carol\n"));
  bool carol_in = false;
  for (int attempt = 0; attempt < 100 && !carol_in; ++attempt) {  // the janitor looks once a second
    carol_in = As(carol_token)->GetServerInfo().ok();
    if (!carol_in) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_TRUE(carol_in);
  EXPECT_EQ(As(kBobToken)->GetServerInfo().status().code(), absl::StatusCode::kUnauthenticated);
  EXPECT_TRUE(As(kAliceToken)->GetServerInfo().ok());
}

// Two authorization headers: which would count depends on their order, so neither does.
TEST_F(AuthTest, TwoAuthorizationHeadersAreRefusedInEitherOrder) {
  Start();
  auto channel = nupmpc::OpenChannel(target_);
  auto stub = v1::MpcService::NewStub(channel);
  for (const auto& [first, second] : {std::pair{kAliceToken, kBobToken}, std::pair{kBobToken, kAliceToken}}) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", absl::StrCat("Bearer ", first));
    context.AddMetadata("authorization", absl::StrCat("Bearer ", second));
    v1::GetServerInfoResponse info;
    const grpc::Status status = stub->GetServerInfo(&context, v1::GetServerInfoRequest(), &info);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAUTHENTICATED) << first;
    EXPECT_THAT(status.error_message(), ::testing::HasSubstr("authorization: given more than once")) << first;
  }
  EXPECT_TRUE(As(kAliceToken)->GetServerInfo().ok());  // one header is fine
}

// A principal removed from the tokens file loses its open Control streams too (within the
// janitor's re-read, about a second), not only its new calls; other principals' streams
// go on.
TEST_F(AuthTest, RemovingATokenEndsItsPrincipalsOpenControlStreams) {
  Start();
  std::unique_ptr<Client> alice = As(kAliceToken), bob = As(kBobToken);
  const auto open = [&](Client& client, grpc::ClientContext* context) {
    auto stream = client.stub().Control(context);
    v1::ControlRequest first;
    *first.mutable_spec() = spec_;
    *first.mutable_step() = StepFrom(inst_.closed_loop->x1[0]);
    EXPECT_TRUE(stream->Write(first));
    v1::ControlResponse answer;
    EXPECT_TRUE(stream->Read(&answer) && answer.result().has_plan());
    return stream;
  };
  grpc::ClientContext alice_context, bob_context;
  // Should the stream never end, the test fails at this deadline instead of hanging.
  bob_context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto alice_stream = open(*alice, &alice_context);
  auto bob_stream = open(*bob, &bob_context);

  const auto removed_at = std::chrono::steady_clock::now();
  WriteTokens(absl::StrCat(kAliceToken, " alice\n", kOpsToken, " ops admin\n"));
  v1::ControlResponse answer;
  while (bob_stream->Read(&answer)) {
  }
  const grpc::Status ended = bob_stream->Finish();
  const double ended_after_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - removed_at).count();
  EXPECT_EQ(ended.error_code(), grpc::StatusCode::UNAUTHENTICATED) << ended.error_message();
  EXPECT_THAT(ended.error_message(), ::testing::HasSubstr("principal \"bob\": its token was removed"));
  EXPECT_LT(ended_after_s, 10.0);  // the janitor looks once a second
  EXPECT_EQ(bob->GetServerInfo().status().code(), absl::StatusCode::kUnauthenticated);

  // Alice's stream still solves.
  v1::ControlRequest next;
  next.set_sequence(2);
  *next.mutable_step() = StepFrom(inst_.closed_loop->x1[1]);
  ASSERT_TRUE(alice_stream->Write(next));
  ASSERT_TRUE(alice_stream->Read(&answer));
  EXPECT_EQ(answer.sequence(), 2u);
  EXPECT_TRUE(answer.result().has_plan());
  alice_stream->WritesDone();
  while (alice_stream->Read(&answer)) {
  }
  EXPECT_TRUE(alice_stream->Finish().ok());
}

TEST_F(AuthTest, BearerTokensNeedTlsOffLoopback) {
  server::ServerOptions o;
  o.address = "0.0.0.0:0";
  o.auth_tokens_file = tokens_file_;
  auto refused = server::GrpcServer::Start(o);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("--auth_tokens_file"), std::string::npos) << refused.status();

  ChannelSecurity token_only;
  token_only.token = kAliceToken;
  auto client = Client::Connect("plant-gw.example:50051", token_only);
  ASSERT_FALSE(client.ok());
  EXPECT_NE(client.status().message().find("token"), std::string::npos) << client.status();
}

// Without authentication every caller may use every session (as before), but ListSessions
// shows a connection only the sessions it created, unless --list_all_sessions.
TEST(ListWithoutAuth, ListSessionsShowsTheCallersConnectionsSessionsUnlessListAll) {
  spdlog::set_level(spdlog::level::warn);
  const v1::ProblemSpec spec = SpecOrDie(LoadInstanceOrDie("masses_N30").problem);
  for (const bool list_all : {false, true}) {
    server::ServerOptions o;
    o.address = "127.0.0.1:0";
    o.grace_period_s = 1.0;
    o.list_all_sessions = list_all;
    auto server = server::GrpcServer::Start(o);
    ASSERT_TRUE(server.ok());
    const std::string target = "127.0.0.1:" + std::to_string((*server)->port());
    ChannelSecurity plaintext;
    auto first = Client::Connect(target, plaintext);
    ASSERT_TRUE(first.ok());
    // Client::Connect's channels share gRPC's subchannel pool; a channel of its own is another connection.
    ChannelOptions own;
    own.own_connection = true;
    Client second(OpenChannel(target, own));
    auto created = (*first)->CreateSession(spec);
    ASSERT_TRUE(created.ok());
    auto mine = (*first)->ListSessions();
    auto theirs = second.ListSessions();
    ASSERT_TRUE(mine.ok() && theirs.ok());
    EXPECT_EQ(mine->size(), 1u);
    EXPECT_EQ(theirs->size(), list_all ? 1u : 0u) << "list_all_sessions=" << list_all;
    EXPECT_TRUE(second.GetSession(created->session_id()).ok());  // usable by id, as before
    (*server)->Shutdown();
  }
}

}  // namespace
}  // namespace nupmpc::testing
