#include "loadtest/echo_process.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "loadtest/echo_server.h"

namespace nupmpc::loadtest {
namespace {

absl::Status Errno(const std::string& what) {
  return absl::InternalError(absl::StrCat(what, ": ", std::strerror(errno)));
}

}  // namespace

absl::StatusOr<std::unique_ptr<EchoProcess>> EchoProcess::Spawn(const std::vector<std::string>& argv,
                                                                const cpu_set_t* cpus) {
  int to_child[2], from_child[2];
  if (pipe(to_child) != 0) return Errno("pipe");
  if (pipe(from_child) != 0) {
    close(to_child[0]);
    close(to_child[1]);
    return Errno("pipe");
  }
  std::vector<char*> args;
  args.reserve(argv.size() + 1);
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const pid_t pid = fork();
  if (pid < 0) {
    const absl::Status failed = Errno("fork");
    for (const int fd : {to_child[0], to_child[1], from_child[0], from_child[1]}) close(fd);
    return failed;
  }
  if (pid == 0) {  // the child: stdin from the parent's pipe, stdout to it
    dup2(to_child[0], STDIN_FILENO);
    dup2(from_child[1], STDOUT_FILENO);
    for (const int fd : {to_child[0], to_child[1], from_child[0], from_child[1]}) close(fd);
    if (cpus != nullptr && sched_setaffinity(0, sizeof(*cpus), cpus) != 0) _exit(126);
    execv(args[0], args.data());
    _exit(127);
  }
  close(to_child[0]);
  close(from_child[1]);
  std::unique_ptr<EchoProcess> p(new EchoProcess());
  p->pid_ = pid;
  p->stdin_fd_ = to_child[1];
  // The first line is the target; EOF before it means the child failed (its stderr says why).
  char c = 0;
  while (read(from_child[0], &c, 1) == 1 && c != '\n') p->target_.push_back(c);
  close(from_child[0]);
  if (c != '\n' || p->target_.empty()) {
    return absl::UnavailableError(absl::StrCat(argv[0], " did not start an echo server"));
  }
  return p;
}

EchoProcess::~EchoProcess() {
  if (stdin_fd_ >= 0) close(stdin_fd_);
  if (pid_ > 0) {
    int status = 0;
    while (waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
  }
}

int ServeEchoUntilStdinCloses(const EchoControlServer& echo) {
  std::printf("%s\n", echo.target().c_str());
  std::fflush(stdout);
  char buffer[64];
  while (read(STDIN_FILENO, buffer, sizeof buffer) > 0) {
  }
  return 0;
}

}  // namespace nupmpc::loadtest
