// TLS and mTLS on the gRPC port, with certificates made at test time by openssl: a TLS
// client is served, a plaintext client or one that trusts another CA is not; mTLS refuses
// clients without a certificate or with one another CA signed, and names the caller by its
// certificate's subject; replacing the certificate files is picked up without a restart.
#include <chrono>
#include <filesystem>
#include <thread>

#include "client/channel_security.h"
#include "gtest/gtest.h"
#include "tests/server/service/service_fixture.h"
#include "tests/util/test_pki.h"

namespace nupmpc::testing {
namespace {

using std::chrono::milliseconds;

class TransportSecurityTest : public ::testing::Test {
 protected:
  void SetUp() override {
    spdlog::set_level(spdlog::level::warn);
    absl::StatusOr<TestPki> pki = TestPki::Create(::testing::TempDir());
    ASSERT_TRUE(pki.ok()) << pki.status();
    pki_ = std::make_unique<TestPki>(*std::move(pki));
    absl::StatusOr<KeyPair> server = pki_->Issue("server", "/CN=localhost", "ca", /*server=*/true);
    ASSERT_TRUE(server.ok()) << server.status();
    server_files_ = *server;
  }
  void TearDown() override {
    if (server_ != nullptr) server_->Shutdown();
    std::filesystem::remove_all(pki_->dir());
  }

  void Start(bool mutual, int reload_interval_s = 10) {
    server::ServerOptions o;
    o.address = "127.0.0.1:0";
    o.grace_period_s = 1.0;
    o.tls.cert_file = server_files_.cert_file;
    o.tls.key_file = server_files_.key_file;
    if (mutual) o.tls.client_ca_file = pki_->CaFile("ca");
    o.tls.reload_interval_s = reload_interval_s;
    absl::StatusOr<std::unique_ptr<server::GrpcServer>> s = server::GrpcServer::Start(o);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
    // The certificate names localhost and 127.0.0.1; an address, not a name, keeps DNS (and
    // c-ares' small per-lookup leak, which LeakSanitizer reports) out of the test.
    target_ = "127.0.0.1:" + std::to_string(server_->port());
  }

  // A new client (a connection of its own) with `security`, its GetServerInfo's status.
  absl::Status InfoWith(const ChannelSecurity& security) {
    absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(target_, security, milliseconds(5000));
    if (!client.ok()) return client.status();
    return (*client)->GetServerInfo().status();
  }
  ChannelSecurity TrustingCa(const std::string& ca) const {
    ChannelSecurity s;
    s.tls_ca_file = pki_->CaFile(ca);
    return s;
  }

  std::unique_ptr<TestPki> pki_;
  KeyPair server_files_;
  std::unique_ptr<server::GrpcServer> server_;
  std::string target_;
};

TEST_F(TransportSecurityTest, ATlsClientIsServedAndAPlaintextOneIsNot) {
  Start(/*mutual=*/false);
  EXPECT_TRUE(InfoWith(TrustingCa("ca")).ok()) << InfoWith(TrustingCa("ca"));

  // A whole Control-stream session over TLS.
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(target_, TrustingCa("ca"));
  ASSERT_TRUE(client.ok()) << client.status();
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  auto session = (*client)->OpenSession(SpecOrDie(inst.problem));
  ASSERT_TRUE(session.ok()) << session.status();
  v1::Step step;
  const Eigen::VectorXd& x = inst.closed_loop->x1.front();
  step.mutable_state()->Add(x.data(), x.data() + x.size());
  auto result = (*session)->Step(step);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->status(), v1::SOLVE_STATUS_CONVERGED);

  EXPECT_EQ(InfoWith({}).code(), absl::StatusCode::kUnavailable);                      // plaintext against TLS
  EXPECT_EQ(InfoWith(TrustingCa("other_ca")).code(), absl::StatusCode::kUnavailable);  // unknown server CA
}

TEST_F(TransportSecurityTest, MutualTlsRefusesClientsWithoutACertificateOfTheClientCa) {
  Start(/*mutual=*/true);
  absl::StatusOr<KeyPair> alice = pki_->Issue("alice", "/CN=alice/O=plant", "ca", /*server=*/false);
  absl::StatusOr<KeyPair> mallory = pki_->Issue("mallory", "/CN=mallory", "other_ca", /*server=*/false);
  ASSERT_TRUE(alice.ok() && mallory.ok());

  EXPECT_EQ(InfoWith(TrustingCa("ca")).code(), absl::StatusCode::kUnavailable);  // no client certificate
  ChannelSecurity as_mallory = TrustingCa("ca");
  as_mallory.tls_cert_file = mallory->cert_file;
  as_mallory.tls_key_file = mallory->key_file;
  EXPECT_EQ(InfoWith(as_mallory).code(), absl::StatusCode::kUnavailable);  // signed by another CA
  ChannelSecurity as_alice = TrustingCa("ca");
  as_alice.tls_cert_file = alice->cert_file;
  as_alice.tls_key_file = alice->key_file;
  ASSERT_TRUE(InfoWith(as_alice).ok()) << InfoWith(as_alice);

  // The certificate's subject is the caller: another subject does not see alice's session.
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(target_, as_alice);
  ASSERT_TRUE(client.ok());
  auto created = (*client)->CreateSession(SpecOrDie(LoadInstanceOrDie("masses_N30").problem));
  ASSERT_TRUE(created.ok()) << created.status();
  absl::StatusOr<KeyPair> bob = pki_->Issue("bob", "/CN=bob/O=plant", "ca", /*server=*/false);
  ASSERT_TRUE(bob.ok());
  ChannelSecurity as_bob = TrustingCa("ca");
  as_bob.tls_cert_file = bob->cert_file;
  as_bob.tls_key_file = bob->key_file;
  absl::StatusOr<std::unique_ptr<Client>> bob_client = Client::Connect(target_, as_bob);
  ASSERT_TRUE(bob_client.ok());
  EXPECT_EQ((*bob_client)->GetSession(created->session_id()).status().code(), absl::StatusCode::kNotFound);
  auto listed = (*bob_client)->ListSessions();
  ASSERT_TRUE(listed.ok());
  EXPECT_TRUE(listed->empty());
  auto own = (*client)->GetSession(created->session_id());
  EXPECT_TRUE(own.ok()) << own.status();
}

// The file-watcher provider re-reads the files: after they are replaced by a certificate
// another CA signed, new connections get the new one (a client trusting only the new CA
// is served, one trusting only the old CA no longer is), with no restart.
TEST_F(TransportSecurityTest, ReplacedCertificateFilesAreServedWithoutARestart) {
  Start(/*mutual=*/false, /*reload_interval_s=*/1);
  ASSERT_TRUE(InfoWith(TrustingCa("ca")).ok());
  ASSERT_FALSE(InfoWith(TrustingCa("other_ca")).ok());

  absl::StatusOr<KeyPair> rotated = pki_->Issue("rotated", "/CN=localhost", "other_ca", /*server=*/true);
  ASSERT_TRUE(rotated.ok()) << rotated.status();
  // Key first, then the certificate, each by rename (as cert-manager and certbot do).
  for (const auto& [from, to] :
       {std::pair{rotated->key_file, server_files_.key_file}, std::pair{rotated->cert_file, server_files_.cert_file}}) {
    std::filesystem::rename(from, to);
  }
  bool served_new = false;
  for (int attempt = 0; attempt < 60 && !served_new; ++attempt) {
    served_new = InfoWith(TrustingCa("other_ca")).ok();
    if (!served_new) std::this_thread::sleep_for(milliseconds(500));
  }
  EXPECT_TRUE(served_new) << "the rotated certificate was not served within 30 s";
  EXPECT_EQ(InfoWith(TrustingCa("ca")).code(), absl::StatusCode::kUnavailable);
}

TEST(TransportSecurityOptions, InconsistentOrUnreadableFilesAreRefusedNamingTheFlag) {
  server::ServerOptions o;
  o.address = "127.0.0.1:0";
  o.tls.cert_file = "/nonexistent/server.pem";
  auto only_cert = server::GrpcServer::Start(o);
  ASSERT_FALSE(only_cert.ok());
  EXPECT_NE(only_cert.status().message().find("--tls_key_file"), std::string::npos) << only_cert.status();

  o.tls.key_file = "/nonexistent/server.key";
  auto unreadable = server::GrpcServer::Start(o);
  ASSERT_FALSE(unreadable.ok());
  EXPECT_NE(unreadable.status().message().find("--tls_cert_file /nonexistent/server.pem"), std::string::npos)
      << unreadable.status();

  server::ServerOptions ca_only;
  ca_only.address = "127.0.0.1:0";
  ca_only.tls.client_ca_file = "/etc/ssl/certs/ca-certificates.crt";
  auto no_cert = server::GrpcServer::Start(ca_only);
  ASSERT_FALSE(no_cert.ok());
  EXPECT_NE(no_cert.status().message().find("--tls_client_ca_file"), std::string::npos) << no_cert.status();
}

TEST(TransportSecurityOptions, LoopbackAndUnixSocketAddressesAreLocal) {
  for (const char* local : {"127.0.0.1:50051", "localhost:1", "[::1]:50051", "unix:/run/nupmpc.sock"}) {
    EXPECT_TRUE(server::IsLocalAddress(local)) << local;
  }
  for (const char* remote : {"[::]:50051", "0.0.0.0:50051", "10.0.0.5:50051", "plant-gw:50051"}) {
    EXPECT_FALSE(server::IsLocalAddress(remote)) << remote;
  }
}

}  // namespace
}  // namespace nupmpc::testing
