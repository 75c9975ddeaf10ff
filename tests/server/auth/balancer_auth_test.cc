// Callers behind a balancer that terminates their TLS: the replica trusts the header
// x-nupmpc-client-subject only from the peer whose client certificate --trusted_balancer_subject
// names. A forwarded subject is the same principal as a direct mTLS caller with that
// certificate; from any other peer the header is ignored; the balancer's certificate alone
// is UNAUTHENTICATED; bearer tokens through the balancer authenticate as they do directly.
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <thread>
#include <tuple>

#include "client/channel_factory.h"
#include "client/session_routing.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/server/service/service_fixture.h"
#include "tests/util/test_pki.h"

namespace nupmpc::testing {
namespace {

constexpr char kAliceToken[] = "alice-0123456789abcdef";

class BalancerAuthTest : public ::testing::Test {
 protected:
  void SetUp() override {
    spdlog::set_level(spdlog::level::warn);
    absl::StatusOr<TestPki> pki = TestPki::Create(::testing::TempDir());
    ASSERT_TRUE(pki.ok()) << pki.status();
    pki_ = std::make_unique<TestPki>(*std::move(pki));
    for (const auto& [name, subject, server] :
         {std::tuple{"server", "/CN=localhost", true}, std::tuple{"balancer", "/CN=nupmpc-balancer/O=test", false},
          std::tuple{"alice", "/CN=alice/O=plant", false}, std::tuple{"bob", "/CN=bob/O=plant", false},
          std::tuple{"mallory", "/CN=mallory/O=plant", false}}) {
      absl::StatusOr<KeyPair> pair = pki_->Issue(name, subject, "ca", server);
      ASSERT_TRUE(pair.ok()) << pair.status();
      keys_[name] = *pair;
      absl::StatusOr<std::string> rfc2253 = TestPki::SubjectOf(pair->cert_file);
      ASSERT_TRUE(rfc2253.ok()) << rfc2253.status();
      subjects_[name] = *rfc2253;
    }
    tokens_file_ = pki_->dir() + "/tokens";
    std::ofstream(tokens_file_) << kAliceToken << " alice\n";
    inst_ = LoadInstanceOrDie("masses_N30");
    spec_ = SpecOrDie(inst_.problem);
  }
  void TearDown() override {
    if (server_ != nullptr) server_->Shutdown();
    std::filesystem::remove_all(pki_->dir());
  }

  server::ServerOptions Options() const {
    server::ServerOptions o;
    o.address = "127.0.0.1:0";
    o.grace_period_s = 1.0;
    o.tls.cert_file = keys_.at("server").cert_file;
    o.tls.key_file = keys_.at("server").key_file;
    o.tls.client_ca_file = pki_->CaFile("ca");
    o.tls.trusted_balancer_subject = subjects_.at("balancer");
    o.auth_tokens_file = tokens_file_;
    return o;
  }
  void Start() {
    absl::StatusOr<std::unique_ptr<server::GrpcServer>> s = server::GrpcServer::Start(Options());
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
    target_ = "127.0.0.1:" + std::to_string(server_->port());
  }

  // A connection presenting `who`'s client certificate.
  std::unique_ptr<v1::MpcService::Stub> StubAs(const std::string& who) {
    ChannelSecurity security;
    security.tls_ca_file = pki_->CaFile("ca");
    security.tls_cert_file = keys_.at(who).cert_file;
    security.tls_key_file = keys_.at(who).key_file;
    absl::StatusOr<std::shared_ptr<grpc::Channel>> channel = OpenChannel(target_, security, {});
    EXPECT_TRUE(channel.ok()) << channel.status();
    return v1::MpcService::NewStub(*channel);
  }
  // A call's context with the forwarded subject and the bearer token, each when given.
  static void Decorate(grpc::ClientContext* context, const std::optional<std::string>& forwarded,
                       const std::optional<std::string>& token) {
    if (forwarded.has_value()) context->AddMetadata("x-nupmpc-client-subject", *forwarded);
    if (token.has_value()) context->AddMetadata("authorization", absl::StrCat("Bearer ", *token));
  }
  grpc::Status GetSession(v1::MpcService::Stub& stub, const std::string& id,
                          const std::optional<std::string>& forwarded = std::nullopt,
                          const std::optional<std::string>& token = std::nullopt) {
    grpc::ClientContext context;
    Decorate(&context, forwarded, token);
    v1::GetSessionRequest request;
    request.set_session_id(id);
    v1::GetSessionResponse info;
    return stub.GetSession(&context, request, &info);
  }
  absl::StatusOr<std::string> CreateSession(v1::MpcService::Stub& stub,
                                            const std::optional<std::string>& forwarded = std::nullopt,
                                            const std::optional<std::string>& token = std::nullopt) {
    grpc::ClientContext context;
    Decorate(&context, forwarded, token);
    v1::CreateSessionRequest request;
    *request.mutable_spec() = spec_;
    v1::CreateSessionResponse response;
    const grpc::Status status = stub.CreateSession(&context, request, &response);
    if (!status.ok()) return absl::InternalError(status.error_message());
    return response.session_id();
  }

  std::unique_ptr<TestPki> pki_;
  std::map<std::string, KeyPair> keys_;
  std::map<std::string, std::string> subjects_;
  std::string tokens_file_;
  bench::BenchmarkInstance inst_;
  v1::ProblemSpec spec_;
  std::unique_ptr<server::GrpcServer> server_;
  std::string target_;
};

TEST_F(BalancerAuthTest, AForwardedSubjectIsThePrincipalOfADirectCallerWithThatCertificate) {
  Start();
  auto alice = StubAs("alice");
  auto balancer = StubAs("balancer");
  absl::StatusOr<std::string> direct = CreateSession(*alice);
  ASSERT_TRUE(direct.ok()) << direct.status();
  absl::StatusOr<std::string> forwarded = CreateSession(*balancer, subjects_["alice"]);
  ASSERT_TRUE(forwarded.ok()) << forwarded.status();

  // Either way in, alice reaches both sessions; bob, forwarded or direct, reaches neither.
  for (const std::string& id : {*direct, *forwarded}) {
    EXPECT_TRUE(GetSession(*alice, id).ok()) << id;
    EXPECT_TRUE(GetSession(*balancer, id, subjects_["alice"]).ok()) << id;
    EXPECT_EQ(GetSession(*balancer, id, subjects_["bob"]).error_code(), grpc::StatusCode::NOT_FOUND) << id;
    EXPECT_EQ(GetSession(*StubAs("bob"), id).error_code(), grpc::StatusCode::NOT_FOUND) << id;
  }
}

TEST_F(BalancerAuthTest, TheHeaderFromAnyOtherPeerIsIgnored) {
  Start();
  absl::StatusOr<std::string> alices = CreateSession(*StubAs("alice"));
  ASSERT_TRUE(alices.ok()) << alices.status();
  auto mallory = StubAs("mallory");
  // Mallory's own certificate decides, not the subject she claims.
  EXPECT_EQ(GetSession(*mallory, *alices, subjects_["alice"]).error_code(), grpc::StatusCode::NOT_FOUND);
  absl::StatusOr<std::string> hers = CreateSession(*mallory, subjects_["alice"]);
  ASSERT_TRUE(hers.ok()) << hers.status();
  EXPECT_EQ(GetSession(*StubAs("alice"), *hers).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(GetSession(*mallory, *hers).ok());
}

TEST_F(BalancerAuthTest, TheBalancersCertificateAloneIsUnauthenticated) {
  Start();
  auto balancer = StubAs("balancer");
  const std::string unknown = NewSessionId();
  for (const std::optional<std::string>& forwarded : {std::optional<std::string>(), std::optional<std::string>("")}) {
    const grpc::Status status = GetSession(*balancer, unknown, forwarded);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAUTHENTICATED) << status.error_message();
    EXPECT_THAT(status.error_message(), ::testing::HasSubstr("the balancer forwarded neither"));
  }
  EXPECT_FALSE(CreateSession(*balancer).ok());
  EXPECT_EQ(server_->state().registry.size(), 0);
}

TEST_F(BalancerAuthTest, TwoForwardedSubjectsAreRefused) {
  Start();
  auto balancer = StubAs("balancer");
  grpc::ClientContext context;
  context.AddMetadata("x-nupmpc-client-subject", subjects_["alice"]);
  context.AddMetadata("x-nupmpc-client-subject", subjects_["bob"]);
  v1::GetServerInfoResponse info;
  const grpc::Status status = balancer->GetServerInfo(&context, v1::GetServerInfoRequest(), &info);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_THAT(status.error_message(), ::testing::HasSubstr("x-nupmpc-client-subject: given more than once"));
}

TEST_F(BalancerAuthTest, BearerTokensThroughTheBalancerAuthenticateAsTheyDoDirectly) {
  Start();
  auto balancer = StubAs("balancer");
  // The token decides even when the balancer also forwards a subject (as for a caller that
  // sent both, and as a direct caller with both gets).
  absl::StatusOr<std::string> id = CreateSession(*balancer, subjects_["bob"], kAliceToken);
  ASSERT_TRUE(id.ok()) << id.status();
  EXPECT_TRUE(GetSession(*StubAs("mallory"), *id, std::nullopt, kAliceToken).ok());
  EXPECT_TRUE(GetSession(*balancer, *id, std::nullopt, kAliceToken).ok());
  EXPECT_EQ(GetSession(*balancer, *id, subjects_["bob"]).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(GetSession(*balancer, *id, std::nullopt, "not-a-token-of-the-file").error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
}

// The balancer's one connection carries many callers' calls (gRPC shares a connection's
// AuthContext among them): each call is who its own headers say, never what an earlier call on
// the connection was. Here a token call comes first; the certificate caller's stream after it
// must not be taken for a token's and ended when that token goes.
TEST_F(BalancerAuthTest, CallersSharingTheBalancersConnectionStayApart) {
  Start();
  auto balancer = StubAs("balancer");
  ASSERT_TRUE(CreateSession(*balancer, std::nullopt, kAliceToken).ok());
  grpc::ClientContext context;
  context.AddMetadata("x-nupmpc-client-subject", subjects_["bob"]);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto stream = balancer->Control(&context);
  v1::ControlRequest request;
  *request.mutable_spec() = spec_;
  const Eigen::VectorXd& x = inst_.closed_loop->x1.front();
  request.mutable_step()->mutable_state()->Add(x.data(), x.data() + x.size());
  v1::ControlResponse answer;
  ASSERT_TRUE(stream->Write(request) && stream->Read(&answer));

  std::ofstream(tokens_file_ + ".new") << "other-0123456789abcdef other\n";
  std::filesystem::rename(tokens_file_ + ".new", tokens_file_);
  // The janitor re-reads the file and ends the streams of removed tokens once a second.
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  v1::ControlRequest next;
  *next.mutable_step() = request.step();
  EXPECT_TRUE(stream->Write(next) && stream->Read(&answer)) << "bob's stream was ended";
  stream->WritesDone();
  while (stream->Read(&answer)) {
  }
  EXPECT_TRUE(stream->Finish().ok());
}

TEST_F(BalancerAuthTest, TheTrustedSubjectNeedsMutualTlsAndMustLookLikeOne) {
  server::ServerOptions no_client_ca = Options();
  no_client_ca.tls.client_ca_file.clear();
  auto refused = server::GrpcServer::Start(no_client_ca);
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.status().message(),
              ::testing::HasSubstr("--trusted_balancer_subject: needs --tls_client_ca_file"));
  for (const char* bad : {"nupmpc-balancer", " CN=nupmpc-balancer"}) {
    server::ServerOptions o = Options();
    o.tls.trusted_balancer_subject = bad;
    auto malformed = server::GrpcServer::Start(o);
    ASSERT_FALSE(malformed.ok()) << bad;
    EXPECT_THAT(malformed.status().message(), ::testing::HasSubstr("--trusted_balancer_subject = ")) << bad;
  }
}

}  // namespace
}  // namespace nupmpc::testing
