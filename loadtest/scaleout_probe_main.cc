// nupmpc-scaleout-probe: the client's view of several replicas behind a balancer, for
// deploy/scaleout-test.sh. Prints one JSON object: see loadtest/failover_probe.h.
//
//   nupmpc-scaleout-probe --server BALANCER --probe streams [--streams 24] [--duration_s 20] [--kinds convex,...]
//     (SIGTERM ends the streams probe before its duration: a script stops it when its scenario is done)
//   nupmpc-scaleout-probe --server BALANCER --probe addressed [--sessions 50] [--solves 20]
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "cli/program_flags.h"
#include "client/problem_file.h"
#include "client/security_flags.h"
#include "loadtest/failover_probe.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "balancer (or server) address host:port (env NUPMPC_SERVER)");
ABSL_FLAG(std::string, instance, "benchmarks/masses_N30.json", "instance whose closed-loop states are sent");
ABSL_FLAG(std::string, probe, "streams", "streams: Control streams through failures; addressed: calls by session id");
ABSL_FLAG(int, streams, 24, "streams probe: concurrent Control streams, each on its own connection");
ABSL_FLAG(double, duration_s, 20.0,
          "streams probe: the longest every stream keeps stepping; SIGTERM ends them sooner, each after its current "
          "step, and the report is printed as after the duration");
ABSL_FLAG(int, verify_every, 25, "streams probe: check every k-th convex plan of a stream against the core (0: none)");
ABSL_FLAG(std::string, kinds, "convex",
          "streams probe: the session kinds the streams take in turn, comma-separated, of: convex, input differences, "
          "keep-out, binary inputs (loadtest/instances/session_kinds.h)");
ABSL_FLAG(int, sessions, 50, "addressed probe: sessions created with client-drawn ids");
ABSL_FLAG(int, solves, 20, "addressed probe: Solve calls by id per session");

namespace {

// Set by SIGTERM: the streams probe ends after each stream's current step.
std::atomic<bool> stop_requested{false};
static_assert(std::atomic<bool>::is_always_lock_free, "set from a signal handler");
void RequestStop(int /*signal*/) { stop_requested.store(true); }

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-scaleout-probe",
    .summary =
        "nupmpc-scaleout-probe: drives replicas behind a balancer through the client library and reports, "
        "as one JSON object, what a controller would have seen: steps answered and failed, sessions "
        "re-created after a replica was lost, and a sample of plans checked against the core solving the "
        "same state (--probe streams); or whether calls addressed by session id all reached their session "
        "(--probe addressed). Used by deploy/scaleout-test.sh.",
    .usage =
        "nupmpc-scaleout-probe --server HOST:PORT [--probe streams|addressed] [--instance FILE] [--tls_ca_file FILE] "
        "[--tls_cert_file FILE --tls_key_file FILE] [--token_file FILE] ...",
    .environment = {{"NUPMPC_SERVER", "address when --server is not given"}},
    .max_arguments = 0,
};

int Fail(const std::string& what, const absl::Status& s) {
  std::fprintf(stderr, "nupmpc-scaleout-probe: %s: %s\n", what.c_str(), s.ToString().c_str());
  return 1;
}

}  // namespace

// The kinds named in --kinds, in that order, from the instance's spec.
absl::StatusOr<std::vector<nupmpc::bench::SessionKind>> ChosenKinds(const nupmpc::v1::ProblemSpec& spec) {
  const std::vector<nupmpc::bench::SessionKind> all = nupmpc::bench::SessionKindsOf(spec);
  std::vector<nupmpc::bench::SessionKind> chosen;
  for (absl::string_view name : absl::StrSplit(absl::GetFlag(FLAGS_kinds), ',', absl::SkipEmpty())) {
    const auto kind = std::find_if(all.begin(), all.end(), [&](const auto& k) { return k.name == name; });
    if (kind == all.end()) return absl::InvalidArgumentError(absl::StrCat("unknown session kind '", name, "'"));
    chosen.push_back(*kind);
  }
  if (chosen.empty()) return absl::InvalidArgumentError("names no session kind");
  return chosen;
}

int main(int argc, char** argv) {
  namespace lt = nupmpc::loadtest;
  if (const char* env = std::getenv("NUPMPC_SERVER"); env != nullptr) absl::SetFlag(&FLAGS_server, env);
  nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  absl::StatusOr<nupmpc::ProblemFile> file = nupmpc::LoadProblemFile(absl::GetFlag(FLAGS_instance));
  if (!file.ok()) return Fail("--instance", file.status());
  absl::StatusOr<nupmpc::ChannelSecurity> security = nupmpc::ChannelSecurityFromFlags();
  if (!security.ok()) return Fail("security flags", security.status());
  lt::ProbeWorkload work{absl::GetFlag(FLAGS_server), *security, file->spec, file->closed_loop_states, {}};
  if (work.states.empty()) {
    const auto& mean = file->spec.initial_state().mean();
    work.states.emplace_back(mean.begin(), mean.end());
  }
  const std::string probe = absl::GetFlag(FLAGS_probe);
  if (probe == "streams") {
    lt::StreamsProbeConfig config;
    config.streams = absl::GetFlag(FLAGS_streams);
    config.duration_s = absl::GetFlag(FLAGS_duration_s);
    config.verify_every = absl::GetFlag(FLAGS_verify_every);
    config.stop = &stop_requested;
    (void)signal(SIGTERM, RequestStop);
    absl::StatusOr<std::vector<nupmpc::bench::SessionKind>> kinds = ChosenKinds(work.spec);
    if (!kinds.ok()) return Fail("--kinds", kinds.status());
    work.kinds = *std::move(kinds);
    absl::StatusOr<lt::StreamsProbeReport> report = lt::RunStreamsProbe(work, config);
    if (!report.ok()) return Fail("streams probe", report.status());
    std::printf("%s\n", lt::ToJson(*report).c_str());
    return 0;
  }
  if (probe == "addressed") {
    absl::StatusOr<lt::AddressedProbeReport> report =
        lt::RunAddressedProbe(work, absl::GetFlag(FLAGS_sessions), absl::GetFlag(FLAGS_solves));
    if (!report.ok()) return Fail("addressed probe", report.status());
    std::printf("%s\n", lt::ToJson(*report).c_str());
    return 0;
  }
  return Fail("--probe", absl::InvalidArgumentError("must be streams or addressed"));
}
