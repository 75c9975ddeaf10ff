#ifndef NUPMPC_TESTS_UTIL_SERVER_PROCESS_H_
#define NUPMPC_TESTS_UTIL_SERVER_PROCESS_H_

// The deployed nupmpc-server as a child process on a loopback port, for the tests that
// kill, restart or signal a real server.

#include <sys/types.h>

#include <chrono>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "grpcpp/channel.h"
#include "tests/util/loopback_port.h"

namespace nupmpc::testing {

class ServerProcess {
 public:
  // Runs `binary --address=127.0.0.1:port flags...` with `env` added to its environment.
  ServerProcess(const std::string& binary, int port, const std::vector<std::string>& flags,
                const std::vector<std::pair<std::string, std::string>>& env = {});
  ~ServerProcess() { Kill(); }
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  std::string target() const { return "127.0.0.1:" + std::to_string(port_); }
  pid_t pid() const { return pid_; }
  // SIGKILL and reap; nothing if it already stopped.
  void Kill();
  // Sends `signal` without waiting for the process.
  void Signal(int signal);
  // Sends `signal` and returns the exit status (128 + signal if killed by one; -1 if it
  // did not exit within 10 s).
  int StopWith(int signal);

 private:
  int port_;
  pid_t pid_ = -1;
};

// Whether `channel` (or a plaintext channel to `target`) connects within `timeout`: the
// server a test started listens.
bool WaitUntilServing(const std::shared_ptr<grpc::Channel>& channel,
                      std::chrono::seconds timeout = std::chrono::seconds(30));
bool WaitUntilServing(const std::string& target, std::chrono::seconds timeout = std::chrono::seconds(30));

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_SERVER_PROCESS_H_
