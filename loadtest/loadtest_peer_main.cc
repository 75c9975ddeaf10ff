// nupmpc-loadtest-peer: a peer server nupmpc-loadtest compares the server under test with,
// run as its child process: it prints its host:port on stdout and serves until its stdin
// closes (loadtest/echo_process.h).
//
//   nupmpc-loadtest-peer --echo_busy_us 0[,US,...] --server HOST:PORT --instance FILE
//       an echo server: answers every step with the server's plan for the instance, after
//       being busy that many microseconds (cycled per step; 0: the transport floor)
//   nupmpc-loadtest-peer --bare
//       a bare server: solves each stream's steps in its own session, nothing else
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/synchronization/mutex.h"
#include "cli/program_flags.h"
#include "client/client.h"
#include "client/problem_file.h"
#include "client/security_flags.h"
#include "loadtest/echo_process.h"
#include "loadtest/echo_server.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "echo: the server whose plan for the instance is the answer");
ABSL_FLAG(std::string, instance, "benchmarks/masses_N30.json", "echo: the instance file whose plan is the answer");
ABSL_FLAG(std::string, echo_busy_us, "",
          "serve as an echo server, busy per step for these microseconds (comma-separated, cycled per step)");
ABSL_FLAG(bool, bare, false, "serve as a bare server that solves each stream's steps in its own session");

namespace {

namespace lt = nupmpc::loadtest;

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-loadtest-peer",
    .summary =
        "nupmpc-loadtest-peer: a peer server nupmpc-loadtest starts as a child process to compare the server "
        "under test with: an echo server answering with the real server's plan (--echo_busy_us) or a bare "
        "solving server (--bare). Prints its host:port on stdout and serves until its stdin closes.",
    .usage = "nupmpc-loadtest-peer --echo_busy_us US[,US...] --server HOST:PORT --instance FILE | --bare",
    .environment = {},
    .max_arguments = 0,
};

int Fail(const std::string& what, const absl::Status& s) {
  std::fprintf(stderr, "nupmpc-loadtest-peer: %s: %s\n", what.c_str(), s.ToString().c_str());
  return 1;
}

absl::StatusOr<std::vector<std::chrono::nanoseconds>> BusyTimes(const std::string& busy_us) {
  std::vector<std::chrono::nanoseconds> busy;
  for (absl::string_view part : absl::StrSplit(busy_us, ',')) {
    double us = 0.0;
    if (!absl::SimpleAtod(part, &us) || !(us >= 0.0)) {
      return absl::InvalidArgumentError(absl::StrCat("\"", part, "\" is not a duration"));
    }
    if (us > 0.0) {
      busy.push_back(
          std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double, std::micro>(us)));
    }
  }
  return busy;
}

// The echo: the real server's plan for the instance is its answer, so messages have their
// real sizes.
int ServeEcho() {
  absl::StatusOr<std::vector<std::chrono::nanoseconds>> busy = BusyTimes(absl::GetFlag(FLAGS_echo_busy_us));
  if (!busy.ok()) return Fail("--echo_busy_us", busy.status());
  absl::StatusOr<nupmpc::ProblemFile> file = nupmpc::LoadProblemFile(absl::GetFlag(FLAGS_instance));
  if (!file.ok()) return Fail("--instance", file.status());
  absl::StatusOr<nupmpc::ChannelSecurity> security = nupmpc::ChannelSecurityFromFlags();
  if (!security.ok()) return Fail("connection security", security.status());
  absl::StatusOr<std::unique_ptr<nupmpc::Client>> connected =
      nupmpc::Client::Connect(absl::GetFlag(FLAGS_server), *security, std::chrono::seconds(10));
  if (!connected.ok()) return Fail("connection security", connected.status());
  absl::StatusOr<nupmpc::v1::SolveResult> answer = (*connected)->SolveOnce(file->spec);
  if (!answer.ok()) return Fail("SolveOnce for the echo server's answer", answer.status());
  absl::StatusOr<std::unique_ptr<lt::EchoControlServer>> echo = lt::EchoControlServer::Start(*std::move(answer), *busy);
  if (!echo.ok()) return Fail("echo server", echo.status());
  return lt::ServeEchoUntilStdinCloses(**echo);
}

}  // namespace

int main(int argc, char** argv) {
  nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  // As nupmpc-server does (see its main): a peer does not pay Abseil's lock-order debugging
  // per request either, so the comparison stays fair.
  absl::SetMutexDeadlockDetectionMode(absl::OnDeadlockCycle::kIgnore);
  if (absl::GetFlag(FLAGS_bare)) {
    absl::StatusOr<std::unique_ptr<lt::EchoControlServer>> bare = lt::EchoControlServer::StartSolving();
    if (!bare.ok()) return Fail("bare server", bare.status());
    return lt::ServeEchoUntilStdinCloses(**bare);
  }
  if (!absl::GetFlag(FLAGS_echo_busy_us).empty()) return ServeEcho();
  return nupmpc::cli::ReportUsageError(kProgram, "--echo_busy_us or --bare is needed");
}
