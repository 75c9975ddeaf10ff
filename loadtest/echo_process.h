#ifndef NUPMPC_LOADTEST_ECHO_PROCESS_H_
#define NUPMPC_LOADTEST_ECHO_PROCESS_H_

// An EchoControlServer in a child process of its own. In the load generator's process the
// echo would share the generator's gRPC threads and pollers, which makes its round trip
// shorter than any separate server's can be (measured at concurrency 1: 126-136 µs
// in-process against 155-166 µs as a process of its own). A peer for nupmpc-server is
// therefore a process, as the server is.

#include <sched.h>
#include <sys/types.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace nupmpc::loadtest {

class EchoProcess {
 public:
  // Runs `argv` (argv[0] the executable), which must print the echo's host:port on its
  // first line of stdout and serve until its stdin closes; on `cpus` when given (the CPUs
  // the server under test has, so that the peer is measured on the same cores).
  static absl::StatusOr<std::unique_ptr<EchoProcess>> Spawn(const std::vector<std::string>& argv,
                                                            const cpu_set_t* cpus = nullptr);
  // Closes the child's stdin and waits for it to exit.
  ~EchoProcess();

  const std::string& target() const { return target_; }

 private:
  EchoProcess() = default;
  pid_t pid_ = -1;
  int stdin_fd_ = -1;
  std::string target_;
};

// The child's side: serves `echo` (already started) until stdin closes, after printing its
// target. Returns the process's exit code.
class EchoControlServer;
int ServeEchoUntilStdinCloses(const EchoControlServer& echo);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_ECHO_PROCESS_H_
