// The nupmpc-server binary as deployed: health reports SERVING, reflection lists the
// service, flags and environment configure it, and SIGTERM drains it to exit 0.
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "client/channel_factory.h"
#include "client/client.h"
#include "client/problem_file.h"
#include "gmock/gmock.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "protos/health_subset.grpc.pb.h"
#include "protos/reflection_subset.grpc.pb.h"
#include "tests/util/raw_http.h"
#include "tests/util/server_process.h"

namespace nupmpc::testing {
namespace {

// The deployed binary with NUPMPC_THREADS set: the environment configures it too.
std::unique_ptr<ServerProcess> StartServer(const char* threads_env) {
  return std::make_unique<ServerProcess>(
      NUPMPC_SERVER_BINARY, FreeLoopbackPort(), std::vector<std::string>{"--log_level=warn", "--grace_period_s=2"},
      std::vector<std::pair<std::string, std::string>>{{"NUPMPC_THREADS", threads_env}});
}

TEST(ServerBinaryTest, HealthReflectionEnvironmentAndGracefulSigterm) {
  const std::unique_ptr<ServerProcess> started = StartServer(/*threads_env=*/"3");
  ServerProcess& server = *started;
  auto channel = nupmpc::OpenChannel(server.target());
  ASSERT_TRUE(WaitUntilServing(channel, std::chrono::seconds(10)));

  auto health = grpc::health::v1::Health::NewStub(channel);
  grpc::ClientContext health_context;
  grpc::health::v1::HealthCheckResponse health_response;
  ASSERT_TRUE(health->Check(&health_context, {}, &health_response).ok());
  EXPECT_EQ(health_response.status(), grpc::health::v1::HealthCheckResponse::SERVING);

  auto reflection = grpc::reflection::v1alpha::ServerReflection::NewStub(channel);
  grpc::ClientContext reflection_context;
  auto stream = reflection->ServerReflectionInfo(&reflection_context);
  grpc::reflection::v1alpha::ServerReflectionRequest list;
  list.set_list_services("");
  ASSERT_TRUE(stream->Write(list));
  grpc::reflection::v1alpha::ServerReflectionResponse listed;
  ASSERT_TRUE(stream->Read(&listed));
  std::vector<std::string> services;
  for (const auto& s : listed.list_services_response().service()) services.push_back(s.name());
  EXPECT_THAT(services, ::testing::Contains("nupmpc.v1.MpcService"));
  stream->WritesDone();
  (void)stream->Finish();

  Client client(channel);
  auto info = client.GetServerInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->limits().worker_threads(), 3u);  // from NUPMPC_THREADS
  EXPECT_EQ(info->api_version(), "nupmpc.v1");

  EXPECT_EQ(server.StopWith(SIGTERM), 0);
}

grpc::health::v1::HealthCheckResponse::ServingStatus HealthOf(grpc::health::v1::Health::Stub& health) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(2));
  grpc::health::v1::HealthCheckResponse response;
  if (!health.Check(&context, {}, &response).ok()) return grpc::health::v1::HealthCheckResponse::UNKNOWN;
  return response.status();
}

// What a load balancer needs to follow a stop: after SIGTERM the health check says
// NOT_SERVING for --drain_delay_s while every call is still served; a second signal
// ends the delay, and the server drains and exits 0.
TEST(ServerBinaryTest, DrainDelayReportsNotServingWhileStillServing) {
  ServerProcess server(NUPMPC_SERVER_BINARY, FreeLoopbackPort(), {"--log_level=warn", "--grace_period_s=2"},
                       {{"NUPMPC_DRAIN_DELAY_S", "60"}});
  auto channel = nupmpc::OpenChannel(server.target());
  ASSERT_TRUE(WaitUntilServing(channel, std::chrono::seconds(10)));
  auto health = grpc::health::v1::Health::NewStub(channel);
  ASSERT_EQ(HealthOf(*health), grpc::health::v1::HealthCheckResponse::SERVING);
  Client client(channel);
  absl::StatusOr<ProblemFile> masses =
      LoadBenchmarkInstanceSpec(std::string(NUPMPC_BENCHMARK_DIR) + "/masses_N30.json");
  ASSERT_TRUE(masses.ok()) << masses.status();
  const v1::ProblemSpec& spec = masses->spec;
  auto created = client.CreateSession(spec);
  ASSERT_TRUE(created.ok()) << created.status();
  absl::StatusOr<v1::GetServerInfoResponse> info = client.GetServerInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_FALSE(info->draining());

  server.Signal(SIGTERM);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (HealthOf(*health) == grpc::health::v1::HealthCheckResponse::SERVING &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_EQ(HealthOf(*health), grpc::health::v1::HealthCheckResponse::NOT_SERVING);
  // One truth: GetServerInfo says draining as the health service does (and nupmpc_draining,
  // read from the same flag).
  info = client.GetServerInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_TRUE(info->draining());
  // Still serving: the existing session solves, and a new one can be made.
  v1::Step step;
  *step.mutable_state() = spec.initial_state().mean();
  auto solved = client.Solve(created->session_id(), step);
  ASSERT_TRUE(solved.ok()) << solved.status();
  EXPECT_TRUE(solved->has_plan());
  EXPECT_TRUE(client.CreateSession(spec).ok());

  // The second signal ends the 60 s delay: exit 0 well within StopWith's 10 s.
  EXPECT_EQ(server.StopWith(SIGTERM), 0);
}

// One SIGTERM: NOT_SERVING at once, and the process serves out the whole delay before it
// drains and exits 0.
TEST(ServerBinaryTest, OneSigtermServesOutTheDrainDelayThenExits) {
  ServerProcess server(NUPMPC_SERVER_BINARY, FreeLoopbackPort(),
                       {"--log_level=warn", "--grace_period_s=1", "--drain_delay_s=1"});
  auto channel = nupmpc::OpenChannel(server.target());
  ASSERT_TRUE(WaitUntilServing(channel, std::chrono::seconds(10)));
  auto health = grpc::health::v1::Health::NewStub(channel);
  ASSERT_EQ(HealthOf(*health), grpc::health::v1::HealthCheckResponse::SERVING);
  const auto signalled = std::chrono::steady_clock::now();
  server.Signal(SIGTERM);
  auto seen = grpc::health::v1::HealthCheckResponse::SERVING;
  while ((seen = HealthOf(*health)) == grpc::health::v1::HealthCheckResponse::SERVING &&
         std::chrono::steady_clock::now() < signalled + std::chrono::seconds(10)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(seen, grpc::health::v1::HealthCheckResponse::NOT_SERVING);
  EXPECT_EQ(server.StopWith(0), 0);  // signal 0: only waits for the exit
  EXPECT_GE(std::chrono::steady_clock::now() - signalled, std::chrono::seconds(1));
}

// After the drain delay the server exits as soon as no work is in flight: an idle connection
// and a Control stream waiting for its next step do not hold it for the grace period (the
// stream ends with an error status).
TEST(ServerBinaryTest, AfterTheDrainDelayAnIdleConnectionAndStreamDoNotHoldTheExit) {
  constexpr int kGraceS = 20;
  ServerProcess server(NUPMPC_SERVER_BINARY, FreeLoopbackPort(),
                       {"--log_level=warn", "--grace_period_s=" + std::to_string(kGraceS), "--drain_delay_s=0.2"});
  auto channel = nupmpc::OpenChannel(server.target());
  ASSERT_TRUE(WaitUntilServing(channel, std::chrono::seconds(10)));
  absl::StatusOr<ProblemFile> masses =
      LoadBenchmarkInstanceSpec(std::string(NUPMPC_BENCHMARK_DIR) + "/masses_N30.json");
  ASSERT_TRUE(masses.ok()) << masses.status();
  // An open Control stream, its first step answered, then idle.
  Client client(channel);
  grpc::ClientContext context;
  auto stream = client.stub().Control(&context);
  v1::ControlRequest first;
  *first.mutable_spec() = masses->spec;
  *first.mutable_step()->mutable_state() = masses->spec.initial_state().mean();
  ASSERT_TRUE(stream->Write(first));
  v1::ControlResponse answer;
  ASSERT_TRUE(stream->Read(&answer));
  ASSERT_TRUE(answer.result().has_plan());

  const auto signalled = std::chrono::steady_clock::now();
  EXPECT_EQ(server.StopWith(SIGTERM), 0);
  const double exit_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - signalled).count();
  // The drain delay plus a moment, far from the grace period (StopWith gives up after 10 s).
  EXPECT_LT(exit_s, kGraceS / 4.0);
  while (stream->Read(&answer)) {
  }
  const grpc::Status ended = stream->Finish();
  EXPECT_FALSE(ended.ok());
  EXPECT_THAT(ended.error_code(), ::testing::AnyOf(grpc::StatusCode::UNAVAILABLE, grpc::StatusCode::CANCELLED))
      << ended.error_message();
}

// Runs the server binary with `flags` until it exits by itself: its exit status (-1 if it
// did not exit within 10 s: then killed) and what it wrote (its log goes to stdout).
std::pair<int, std::string> RunUntilExit(const std::vector<std::string>& flags) {
  std::vector<char*> argv = {const_cast<char*>(NUPMPC_SERVER_BINARY)};  // built before fork: the child only execs
  for (const std::string& f : flags) argv.push_back(const_cast<char*>(f.c_str()));
  argv.push_back(nullptr);
  std::array<int, 2> errors{};
  if (pipe2(errors.data(), O_CLOEXEC) != 0) return {-1, "pipe2 failed"};
  const pid_t pid = fork();
  if (pid < 0) {
    close(errors[0]);
    close(errors[1]);
    return {-1, "fork failed"};
  }
  if (pid == 0) {
    dup2(errors[1], STDOUT_FILENO);
    dup2(errors[1], STDERR_FILENO);
    execv(NUPMPC_SERVER_BINARY, argv.data());
    _exit(127);
  }
  close(errors[1]);
  // Read until the server exits (end of file), or kill it at the deadline.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  std::string written;
  std::array<char, 4096> chunk{};
  for (;;) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    pollfd readable{.fd = errors[0], .events = POLLIN, .revents = 0};
    const int ready = left.count() > 0 ? poll(&readable, 1, static_cast<int>(left.count())) : 0;
    if (ready < 0 && errno == EINTR) continue;
    if (ready <= 0) {
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
      close(errors[0]);
      return {-1, written};
    }
    const ssize_t n = read(errors[0], chunk.data(), chunk.size());
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    written.append(chunk.data(), static_cast<std::size_t>(n));
  }
  close(errors[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status), written};
}

bool AcceptsConnections(int port) {
  const int sock = ConnectLoopback(port);
  if (sock >= 0) close(sock);
  return sock >= 0;
}

// Sessions live in one process: a second server given a port in use must not start and
// take part of the first one's connections (gRPC and httplib bind with SO_REUSEPORT unless
// told not to, and start when any one of an address's resolved addresses binds: see
// listen_probe_test for the latter), and the operator learns why it did not start.
TEST(ServerBinaryTest, ASecondServerOnAPortInUseRefusesToStart) {
  const int metrics_port = FreeLoopbackPort();
  const std::string metrics_address = "--metrics_address=127.0.0.1:" + std::to_string(metrics_port);
  ServerProcess first(NUPMPC_SERVER_BINARY, FreeLoopbackPort(),
                      {"--log_level=warn", "--grace_period_s=1", metrics_address});
  auto channel = nupmpc::OpenChannel(first.target());
  ASSERT_TRUE(WaitUntilServing(channel, std::chrono::seconds(10)));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!AcceptsConnections(metrics_port) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(AcceptsConnections(metrics_port));

  const auto [grpc_status, grpc_errors] = RunUntilExit({"--address=" + first.target(), "--log_level=warn"});
  EXPECT_EQ(grpc_status, 1) << grpc_errors;
  EXPECT_THAT(grpc_errors, ::testing::HasSubstr("could not listen on --address " + first.target() + ": " +
                                                first.target() + " is in use by another process"))
      << grpc_errors;

  const auto [metrics_status, metrics_errors] =
      RunUntilExit({"--address=127.0.0.1:0", "--log_level=warn", metrics_address});
  EXPECT_EQ(metrics_status, 1) << metrics_errors;
  const std::string metrics_in_use = "127.0.0.1:" + std::to_string(metrics_port);
  EXPECT_THAT(metrics_errors, ::testing::HasSubstr("could not listen on --metrics_address " + metrics_in_use + ": " +
                                                   metrics_in_use + " is in use by another process"))
      << metrics_errors;

  EXPECT_TRUE(Client(channel).GetServerInfo().ok());  // the first one serves on
  EXPECT_EQ(first.StopWith(SIGTERM), 0);
}

// Another server on IPv6's loopback only: given [::]:PORT, gRPC would listen on IPv4
// alone and start; clients reaching [::1] would talk to the other server.
TEST(ServerBinaryTest, AServerWhosePortIsHeldOnOneFamilyRefusesToStart) {
  const int held = socket(AF_INET6, SOCK_STREAM | SOCK_CLOEXEC, 0);
  const int yes = 1;
  sockaddr_in6 addr{};
  addr.sin6_family = AF_INET6;
  addr.sin6_addr = in6addr_loopback;
  socklen_t length = sizeof(addr);
  if (held < 0 || setsockopt(held, IPPROTO_IPV6, IPV6_V6ONLY, &yes, sizeof(yes)) != 0 ||
      bind(held, reinterpret_cast<sockaddr*>(&addr), length) != 0) {
    // No IPv6 (loopback) on this machine: nobody can hold a port there, so the case cannot
    // arise; the server then starts on IPv4 (checked by the suite's other tests).
    EXPECT_THAT(errno, ::testing::AnyOf(EADDRNOTAVAIL, EAFNOSUPPORT));
    if (held >= 0) close(held);
    return;
  }
  const bool listening = listen(held, 4) == 0 && getsockname(held, reinterpret_cast<sockaddr*>(&addr), &length) == 0;
  const std::string port = std::to_string(ntohs(addr.sin6_port));
  const auto [status, errors] =
      listening ? RunUntilExit({"--address=[::]:" + port, "--log_level=warn"}) : std::pair<int, std::string>{};
  close(held);
  ASSERT_TRUE(listening);
  EXPECT_EQ(status, 1) << errors;
  EXPECT_THAT(errors, ::testing::HasSubstr("could not listen on --address [::]:" + port + ": [::]:" + port +
                                           " is in use by another process"))
      << errors;
}

// Minimal containers have no /etc/hosts: a name that does not resolve is refused at start-up
// naming it, for the service's and the metrics' address alike.
TEST(ServerBinaryTest, AnAddressThatDoesNotResolveIsRefusedAtStartup) {
  for (const std::string flag : {"--address", "--metrics_address"}) {
    std::vector<std::string> args = {flag + "=no-such-host.invalid:5", "--log_level=warn"};
    if (flag == "--metrics_address") args.push_back("--address=127.0.0.1:0");
    const auto [status, errors] = RunUntilExit(args);
    EXPECT_EQ(status, 1) << errors;
    EXPECT_THAT(errors, ::testing::HasSubstr("could not listen on " + flag +
                                             " no-such-host.invalid:5: the host "
                                             "'no-such-host.invalid' does not resolve"))
        << errors;
  }
}

TEST(ServerBinaryTest, BadFlagValuesAreRefusedAtStartup) {
  for (const char* bad : {"--threads=0", "--drain_delay_s=nan", "--drain_delay_s=1e9", "--grace_period_s=-1"}) {
    const pid_t pid = fork();
    if (pid == 0) {
      execl(NUPMPC_SERVER_BINARY, NUPMPC_SERVER_BINARY, bad, "--log_level=off", static_cast<char*>(nullptr));
      _exit(127);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    ASSERT_TRUE(WIFEXITED(status)) << bad;
    EXPECT_EQ(WEXITSTATUS(status), 2) << bad;
  }
}

}  // namespace
}  // namespace nupmpc::testing
