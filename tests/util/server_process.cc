#include "tests/util/server_process.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <thread>

#include "client/channel_factory.h"

namespace nupmpc::testing {

ServerProcess::ServerProcess(const std::string& binary, int port, const std::vector<std::string>& flags,
                             const std::vector<std::pair<std::string, std::string>>& env)
    : port_(port) {
  std::vector<std::string> args = {binary, "--address=" + target()};
  args.insert(args.end(), flags.begin(), flags.end());
  pid_ = fork();
  if (pid_ == 0) {
    for (const auto& [name, value] : env) setenv(name.c_str(), value.c_str(), 1);
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(binary.c_str(), argv.data());
    _exit(127);
  }
}

void ServerProcess::Kill() {
  if (pid_ <= 0) return;
  kill(pid_, SIGKILL);
  waitpid(pid_, nullptr, 0);
  pid_ = -1;
}

void ServerProcess::Signal(int signal) {
  if (pid_ > 0) kill(pid_, signal);
}

int ServerProcess::StopWith(int signal) {
  if (pid_ <= 0) return -1;
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

bool WaitUntilServing(const std::shared_ptr<grpc::Channel>& channel, std::chrono::seconds timeout) {
  return channel->WaitForConnected(std::chrono::system_clock::now() + timeout);
}

bool WaitUntilServing(const std::string& target, std::chrono::seconds timeout) {
  return WaitUntilServing(nupmpc::OpenChannel(target), timeout);
}

}  // namespace nupmpc::testing
