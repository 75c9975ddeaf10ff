// The nupmpc-server binary as deployed: health reports SERVING, reflection lists the
// service, flags and environment configure it, and SIGTERM drains it to exit 0.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <thread>

#include "client/client.h"
#include "gmock/gmock.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "protos/health_subset.grpc.pb.h"
#include "protos/reflection_subset.grpc.pb.h"

namespace nupmpc::testing {
namespace {

// Picks a free loopback port: bind to port 0 and ask which one the kernel chose.
int FreePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t length = sizeof(address);
  if (bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0 ||
      getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length) != 0) {
    close(fd);
    return 0;
  }
  close(fd);
  return ntohs(address.sin_port);
}

class ServerProcess {
 public:
  explicit ServerProcess(int port, const char* threads_env) : port_(port) {
    pid_ = fork();
    if (pid_ == 0) {
      if (threads_env != nullptr) setenv("NUPMPC_THREADS", threads_env, 1);
      const std::string address = "--address=127.0.0.1:" + std::to_string(port);
      execl(NUPMPC_SERVER_BINARY, NUPMPC_SERVER_BINARY, address.c_str(), "--log_level=warn", "--grace_period_s=2",
            static_cast<char*>(nullptr));
      _exit(127);
    }
  }
  ~ServerProcess() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  std::string target() const { return "127.0.0.1:" + std::to_string(port_); }
  // Sends `signal` and returns the exit status (-1 if it did not exit within 10 s).
  int StopWith(int signal) {
    kill(pid_, signal);
    for (int i = 0; i < 1000; ++i) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return -1;
  }

 private:
  int port_;
  pid_t pid_ = -1;
};

bool WaitUntilServing(const std::shared_ptr<grpc::Channel>& channel) {
  return channel->WaitForConnected(std::chrono::system_clock::now() + std::chrono::seconds(10));
}

TEST(ServerBinaryTest, HealthReflectionEnvironmentAndGracefulSigterm) {
  ServerProcess server(FreePort(), /*threads_env=*/"3");
  auto channel = grpc::CreateChannel(server.target(), grpc::InsecureChannelCredentials());
  ASSERT_TRUE(WaitUntilServing(channel));

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

TEST(ServerBinaryTest, BadFlagValuesAreRefusedAtStartup) {
  const pid_t pid = fork();
  if (pid == 0) {
    execl(NUPMPC_SERVER_BINARY, NUPMPC_SERVER_BINARY, "--threads=0", static_cast<char*>(nullptr));
    _exit(127);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 2);
}

}  // namespace
}  // namespace nupmpc::testing
