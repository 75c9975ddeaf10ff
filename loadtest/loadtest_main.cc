// nupmpc-loadtest: drives a running nupmpc-server with concurrent Control streams and
// reports throughput and latency next to the core's own solve time for the same steps.
//
//   nupmpc-loadtest [--server HOST:PORT] [--instance FILE] [--concurrency C | --sweep 1,2,8,64]
//                   [--mode closed|open [--rate R | --rate_x X]] [--duration_s T] [--requests R]
//                   [--json]
//   nupmpc-loadtest --idle_sessions 10000 [--idle_release close|expire]
//
// Every stream creates its own session from the instance and cycles through the
// instance's recorded closed-loop states (or, for a file without them, its initial state).
#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <numeric>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/synchronization/mutex.h"
#include "cli/program_flags.h"
#include "client/client.h"
#include "client/problem_file.h"
#include "client/security_flags.h"
#include "loadtest/core_baseline.h"
#include "loadtest/echo_process.h"
#include "loadtest/idle_sessions.h"
#include "loadtest/interleaved_runs.h"
#include "loadtest/load_level.h"
#include "loadtest/loadtest_report.h"
#include "loadtest/transport_floor.h"
#include "server/scheduling/cpu_affinity.h"

ABSL_FLAG(std::string, server, "127.0.0.1:50051", "server address host:port (env NUPMPC_SERVER)");
ABSL_FLAG(std::string, instance, "benchmarks/masses_N30.json",
          "benchmark instance or ProblemSpec JSON every stream solves");
ABSL_FLAG(int, concurrency, 1, "concurrent streams (sessions)");
ABSL_FLAG(std::string, sweep, "",
          "comma-separated concurrency levels, run one after another (overrides --concurrency)");
ABSL_FLAG(std::string, mode, "closed", "closed: next state when the answer arrives; open: Poisson arrivals");
ABSL_FLAG(double, rate, 0.0, "open loop: total arrivals per second");
ABSL_FLAG(double, rate_x, 0.0,
          "open loop: arrivals as a multiple of the capacity (solver cores on the server's CPUs) / core median solve "
          "time");
ABSL_FLAG(double, duration_s, 5.0, "measured seconds per level");
ABSL_FLAG(double, warmup_s, 0.5, "unmeasured seconds before each level");
ABSL_FLAG(int, rounds, 3,
          "each level alternates the server under test and its peers (--echo, --inline_solve, --bare_solve) this "
          "many times, "
          "each run for duration_s / rounds, and reports the runs of each merged: a machine whose speed drifts "
          "between minutes then slows all of them alike");
ABSL_FLAG(uint64_t, requests, 0, "stop a level once this many solves were answered (0: by time)");
ABSL_FLAG(int, baseline_rounds, 20,
          "passes of the core-alone baseline over the closed-loop states (--fleet: periods of the core stepping the "
          "sessions in turn, at least one pass over the states)");
ABSL_FLAG(int, transport_calls, 2000, "health checks that measure gRPC's own round trip");
ABSL_FLAG(bool, echo, true,
          "also run every level against a zero-work echo server in a child process (the transport floor at that load)");
ABSL_FLAG(bool, inline_solve, false,
          "also run every level against the echo server busy inside its reaction, for each step, for the core's own "
          "time for that step (a server that solves where the request arrives: the lowest round trip any design "
          "could reach for the same work)");
ABSL_FLAG(bool, bare_solve, false,
          "also run every level against a bare server in a child process: each stream's session built from its "
          "spec and each step solved in the gRPC reaction as nupmpc-server's SolveStep does, and nothing else (no "
          "worker pool, registry, admission, deadlines, metrics): what the server's own machinery costs");
ABSL_FLAG(bool, new_references, false,
          "every step also sends new output references (the instance's output priors with a moving target)");
ABSL_FLAG(std::string, server_cpus, "",
          "CPU list (e.g. 0) of the server under test: the echo peers and the core-alone baseline run there, so all "
          "are measured on the same cores (start nupmpc-server with taskset -c on the same list); empty: not pinned");
ABSL_FLAG(std::string, client_cpus, "",
          "CPU list (e.g. 1) this load generator runs on, apart from the server's; empty: wherever it may");
ABSL_FLAG(int, fleet, 0,
          "fleet mode: step this many sessions per SolveFleet call (closed loop), then the same number of "
          "separate Control streams, and compare");
ABSL_FLAG(int, fleet_calls_in_flight, 1,
          "fleet mode: the --fleet sessions in this many SolveFleet calls at once, each caller closed-loop on its own "
          "connection (1: one call per period, as one supervisory controller; 2: the server has the next call while "
          "a caller handles its answer, which measures the server's throughput)");
ABSL_FLAG(bool, json, false, "print one JSON document instead of the table");
ABSL_FLAG(std::string, progress, "auto",
          "status line every second on stderr: on, off, auto (when stderr is a terminal)");
ABSL_FLAG(int, idle_sessions, 0, "memory mode: create this many idle sessions, release them, report server RSS");
ABSL_FLAG(std::string, idle_release, "close", "memory mode: close (CloseSession) or expire (wait for idle expiry)");
ABSL_FLAG(uint64_t, seed, 1, "open-loop arrival seed");

namespace {

namespace lt = nupmpc::loadtest;

const nupmpc::cli::ProgramInfo kProgram{
    .name = "nupmpc-loadtest",
    .summary =
        "nupmpc-loadtest: drives a running nupmpc-server with concurrent Control streams and reports "
        "throughput and latency next to the core's own solve time for the same steps (and, with --echo, "
        "the transport floor of a zero-work server at the same load). Every stream creates its own "
        "session from --instance and cycles through the instance's recorded closed-loop states (or its "
        "initial state). --idle_sessions N instead measures the server's memory per idle session. Exit "
        "status 3: a closed-loop level starved a stream (one served under half or over twice the mean).",
    .usage =
        "nupmpc-loadtest [--server HOST:PORT] [--instance FILE] [--concurrency C | --sweep 1,2,8,64] "
        "[--mode closed|open [--rate R | --rate_x X]] [--duration_s T] [--json] | --idle_sessions N",
    .environment = {{"NUPMPC_SERVER", "server address when --server is not given"}},
    .max_arguments = 0,
};

int Fail(const std::string& what, const absl::Status& s) {
  std::fprintf(stderr, "nupmpc-loadtest: %s: %s\n", what.c_str(), s.ToString().c_str());
  return 1;
}

// Exit status 3 when a level starved a stream (lt::StarvedAStream), after every level ran:
// the figures are printed either way, and a script that runs the load test fails.
int ReportStarvedStreams(const std::vector<lt::LevelReport>& levels) {
  int status = 0;
  for (const lt::LevelReport& l : levels) {
    if (!lt::StarvedAStream(l)) continue;
    std::fprintf(stderr,
                 "nupmpc-loadtest: concurrency %d starved a stream: the least served got %.2f, the most %.2f of the "
                 "mean (a fair server stays within a factor %.0f)\n",
                 l.config.concurrency, l.stream_min_share, l.stream_max_share, lt::kFairShareFactor);
    status = 3;
  }
  return status;
}

absl::StatusOr<std::vector<int>> ConcurrencyLevels() {
  const std::string sweep = absl::GetFlag(FLAGS_sweep);
  if (sweep.empty()) return std::vector<int>{absl::GetFlag(FLAGS_concurrency)};
  std::vector<int> levels;
  for (absl::string_view part : absl::StrSplit(sweep, ',', absl::SkipWhitespace())) {
    int c = 0;
    if (!absl::SimpleAtoi(part, &c) || c < 1) {
      return absl::InvalidArgumentError(absl::StrCat("--sweep: \"", part, "\" is not a positive integer"));
    }
    levels.push_back(c);
  }
  if (levels.empty()) return absl::InvalidArgumentError("--sweep: no levels");
  return levels;
}

bool ShowProgress() {
  const std::string p = absl::GetFlag(FLAGS_progress);
  return p == "on" || (p == "auto" && isatty(STDERR_FILENO));
}

}  // namespace

// --client_cpus for this process (before any thread is started: they inherit it) and the
// set of --server_cpus (nullopt when not given).
absl::StatusOr<std::optional<cpu_set_t>> PinProcess() {
  if (const std::string client = absl::GetFlag(FLAGS_client_cpus); !client.empty()) {
    absl::StatusOr<cpu_set_t> set = nupmpc::server::ParseCpuList(client);
    if (!set.ok()) return set.status();
    if (absl::Status pinned = nupmpc::server::PinCallingThread(*set); !pinned.ok()) return pinned;
  }
  const std::string server = absl::GetFlag(FLAGS_server_cpus);
  if (server.empty()) return std::nullopt;
  absl::StatusOr<cpu_set_t> set = nupmpc::server::ParseCpuList(server);
  if (!set.ok()) return set.status();
  return *set;
}

int main(int argc, char** argv) {
  if (const char* env = std::getenv("NUPMPC_SERVER"); env != nullptr) absl::SetFlag(&FLAGS_server, env);
  nupmpc::cli::ParseProgramFlags(kProgram, argc, argv);
  // As nupmpc-server does (see its main): the generator and the peers do not pay Abseil's
  // lock-order debugging per request either, so the comparison stays fair.
  absl::SetMutexDeadlockDetectionMode(absl::OnDeadlockCycle::kIgnore);
  const absl::StatusOr<std::optional<cpu_set_t>> server_cpus = PinProcess();
  if (!server_cpus.ok()) return Fail("--server_cpus/--client_cpus", server_cpus.status());
  const std::string generator_cpus = nupmpc::server::CallingThreadCpuList();
  const std::string target = absl::GetFlag(FLAGS_server);
  const std::string instance_path = absl::GetFlag(FLAGS_instance);
  absl::StatusOr<nupmpc::ProblemFile> file = nupmpc::LoadProblemFile(instance_path);
  if (!file.ok()) return Fail("--instance", file.status());
  if (file->closed_loop_states.empty()) {
    const auto& mean = file->spec.initial_state().mean();
    file->closed_loop_states.emplace_back(mean.begin(), mean.end());
  }
  const std::string name = std::filesystem::path(instance_path).stem().string();
  absl::StatusOr<nupmpc::ChannelSecurity> security = nupmpc::ChannelSecurityFromFlags();
  if (!security.ok()) return Fail("connection security", security.status());
  const bool json = absl::GetFlag(FLAGS_json);

  if (const int idle = absl::GetFlag(FLAGS_idle_sessions); idle > 0) {
    const std::string release = absl::GetFlag(FLAGS_idle_release);
    if (release != "close" && release != "expire") {
      return Fail("--idle_release", absl::InvalidArgumentError("must be close or expire"));
    }
    absl::StatusOr<lt::IdleSessionsReport> r = lt::RunIdleSessions(target, file->spec, idle, release == "expire");
    if (!r.ok()) return Fail("idle sessions", r.status());
    lt::PrintIdleSessions(name, *r, json);
    return 0;
  }

  absl::StatusOr<std::vector<int>> levels = ConcurrencyLevels();
  if (!levels.ok()) return Fail("--sweep", levels.status());
  const std::string mode = absl::GetFlag(FLAGS_mode);
  if (mode != "closed" && mode != "open") return Fail("--mode", absl::InvalidArgumentError("must be closed or open"));
  if (const int fleet = absl::GetFlag(FLAGS_fleet), in_flight = absl::GetFlag(FLAGS_fleet_calls_in_flight);
      in_flight != 1 && (in_flight < 1 || in_flight > fleet)) {
    return Fail("--fleet_calls_in_flight",
                absl::InvalidArgumentError(absl::StrCat(in_flight, ": from 1 to the --fleet sessions (", fleet, ")")));
  }

  absl::StatusOr<std::unique_ptr<nupmpc::Client>> client =
      nupmpc::Client::Connect(target, *security, std::chrono::seconds(10));
  if (!client.ok()) return Fail("connection security", client.status());
  absl::StatusOr<nupmpc::v1::GetServerInfoResponse> info = (*client)->GetServerInfo();
  if (!info.ok()) return Fail(absl::StrCat("server ", target), info.status());

  absl::StatusOr<lt::CoreBaseline> baseline = lt::MeasuredOn(*server_cpus, [&] {
    return lt::MeasureCoreBaseline(file->spec, file->closed_loop_states, absl::GetFlag(FLAGS_baseline_rounds),
                                   absl::GetFlag(FLAGS_new_references));
  });
  if (!baseline.ok()) return Fail("core baseline", baseline.status());
  // A server without ServerLimits.solver_cores runs at most its workers' solves at once.
  const int solver_cores = static_cast<int>(info->limits().solver_cores() > 0 ? info->limits().solver_cores()
                                                                              : info->limits().worker_threads());
  const int solve_cores = lt::UsableCores(solver_cores, info->cpus());
  const int fleet_cores = lt::UsableCores(static_cast<int>(info->limits().worker_threads()), info->cpus());
  const double capacity_per_s = solve_cores / (baseline->median_ms * 1e-3);

  absl::StatusOr<lt::TransportFloor> transport =
      lt::MeasureTransportFloor(target, absl::GetFlag(FLAGS_transport_calls), *security);
  if (!transport.ok()) return Fail("transport floor", transport.status());

  // The peers are nupmpc-loadtest-peer child processes (installed beside this program): echo
  // servers answering with the real server's plan for the instance (real message sizes), or
  // a bare solving server.
  const std::string peer_program =
      (std::filesystem::read_symlink("/proc/self/exe").parent_path() / "nupmpc-loadtest-peer").string();
  std::unique_ptr<lt::EchoProcess> echo;
  const auto spawn_echo = [&](const std::string& busy_us) {
    std::vector<std::string> args = {peer_program, "--server=" + target, "--instance=" + instance_path,
                                     "--echo_busy_us=" + busy_us};
    for (std::string& a : nupmpc::SecurityFlagArguments()) args.push_back(std::move(a));
    return lt::EchoProcess::Spawn(args, server_cpus->has_value() ? &**server_cpus : nullptr);
  };
  if (absl::GetFlag(FLAGS_echo)) {
    absl::StatusOr<std::unique_ptr<lt::EchoProcess>> started = spawn_echo("0");
    if (!started.ok()) return Fail("echo server", started.status());
    echo = *std::move(started);
  }
  std::unique_ptr<lt::EchoProcess> bare;
  if (absl::GetFlag(FLAGS_bare_solve)) {
    absl::StatusOr<std::unique_ptr<lt::EchoProcess>> started =
        lt::EchoProcess::Spawn({peer_program, "--bare"}, server_cpus->has_value() ? &**server_cpus : nullptr);
    if (!started.ok()) return Fail("bare server", started.status());
    bare = *std::move(started);
  }
  // The inline peer of a level: busy for the core's own time for each state, in the order
  // every stream sends them, measured with as many sessions stepped in turn as the level
  // has streams (the server's sessions' data are that cold between their steps).
  struct InlinePeer {
    lt::CoreBaseline core;
    std::unique_ptr<lt::EchoProcess> process;
  };
  const auto inline_peer_for = [&](int streams) -> absl::StatusOr<InlinePeer> {
    InlinePeer peer{.core = *baseline, .process = nullptr};
    if (streams > 1) {
      const int rounds = std::max(1, (absl::GetFlag(FLAGS_baseline_rounds) + streams - 1) / streams);
      absl::StatusOr<lt::CoreBaseline> in_turn = lt::MeasuredOn(*server_cpus, [&] {
        return lt::MeasureCoreBaseline(file->spec, file->closed_loop_states, rounds,
                                       absl::GetFlag(FLAGS_new_references), streams);
      });
      if (!in_turn.ok()) return in_turn.status();
      peer.core = *std::move(in_turn);
    }
    absl::StatusOr<std::unique_ptr<lt::EchoProcess>> started = spawn_echo(
        absl::StrJoin(peer.core.state_ms, ",", [](std::string* out, double ms) { absl::StrAppend(out, ms * 1e3); }));
    if (!started.ok()) return started.status();
    peer.process = *std::move(started);
    return peer;
  };

  const lt::RunHeader header{.instance = name,
                             .target = target,
                             .server = *info,
                             .baseline = *baseline,
                             .transport = *transport,
                             .solve_cores = solve_cores,
                             .fleet_cores = fleet_cores,
                             .capacity_per_s = capacity_per_s,
                             .echo = echo != nullptr,
                             .inline_solve = absl::GetFlag(FLAGS_inline_solve),
                             .bare = bare != nullptr,
                             .peer_cpus = server_cpus->has_value() ? nupmpc::server::CpuList(**server_cpus) : "",
                             .generator_cpus = generator_cpus,
                             .rounds = std::max(1, absl::GetFlag(FLAGS_rounds))};
  if (!json) lt::PrintHeader(header);
  const lt::StreamPlan plan{&file->spec, &file->closed_loop_states, mode == "closed",
                            absl::GetFlag(FLAGS_new_references)};
  if (const int fleet = absl::GetFlag(FLAGS_fleet); fleet > 0) {
    const lt::FleetRunOptions options{.sessions = fleet,
                                      .calls_in_flight = absl::GetFlag(FLAGS_fleet_calls_in_flight),
                                      .rounds = absl::GetFlag(FLAGS_rounds),
                                      .duration_s = absl::GetFlag(FLAGS_duration_s),
                                      .warmup_s = absl::GetFlag(FLAGS_warmup_s),
                                      .baseline_rounds = absl::GetFlag(FLAGS_baseline_rounds)};
    absl::StatusOr<lt::FleetRuns> runs = lt::RunFleetInterleaved(target, *security, plan, *file, options, *server_cpus);
    if (!runs.ok()) return Fail("fleet level", runs.status());
    lt::PrintFleet(header, runs->fleet, runs->separate, runs->core, json);
    return ReportStarvedStreams({runs->separate});
  }
  std::vector<lt::LevelReport> reports;
  for (const int c : *levels) {
    lt::LevelConfig config;
    config.concurrency = c;
    config.closed_loop = plan.closed_loop;
    config.rate_per_s = absl::GetFlag(FLAGS_rate);
    if (absl::GetFlag(FLAGS_rate_x) > 0.0) config.rate_per_s = absl::GetFlag(FLAGS_rate_x) * capacity_per_s;
    config.duration_s = absl::GetFlag(FLAGS_duration_s);
    config.warmup_s = absl::GetFlag(FLAGS_warmup_s);
    config.requests = absl::GetFlag(FLAGS_requests);
    config.progress = ShowProgress();
    config.seed = absl::GetFlag(FLAGS_seed);
    config.security = *security;
    std::optional<InlinePeer> inline_solve;
    if (absl::GetFlag(FLAGS_inline_solve)) {
      absl::StatusOr<InlinePeer> started = inline_peer_for(c);
      if (!started.ok()) return Fail(absl::StrCat("inline-solve echo server, concurrency ", c), started.status());
      inline_solve = *std::move(started);
    }
    absl::StatusOr<lt::LevelRuns> runs = lt::RunInterleaved(
        target, {echo.get(), inline_solve.has_value() ? inline_solve->process.get() : nullptr, bare.get()}, plan,
        config, absl::GetFlag(FLAGS_rounds));
    if (!runs.ok()) return Fail(absl::StrCat("concurrency ", c), runs.status());
    lt::LevelReport& report = runs->server;
    if (inline_solve.has_value()) {
      const std::vector<double>& busy = inline_solve->core.state_ms;
      report.inline_core = lt::LevelCore{
          .median_ms = inline_solve->core.median_ms,
          .mean_ms = inline_solve->core.mean_ms,
          .busy_mean_ms = busy.empty() ? 0.0 : std::accumulate(busy.begin(), busy.end(), 0.0) / busy.size(),
          .sessions = c};
    }
    if (!json) lt::PrintLevel(header, report);
    for (const auto& [peer, slot, label, busy_ms] :
         {std::tuple{&runs->peers[0], &report.echo, "echo", 0.0},
          std::tuple{&runs->peers[1], &report.inline_solve, "inline", report.inline_core.median_ms},
          std::tuple{&runs->peers[2], &report.bare, "bare",
                     report.inline_core.sessions > 0 ? report.inline_core.median_ms : header.baseline.median_ms}}) {
      if (!peer->has_value()) continue;
      if (!json) lt::PrintPeerLevel(label, **peer, busy_ms);
      *slot = std::make_shared<const lt::LevelReport>(std::move(**peer));
    }
    if (!json) lt::PrintRatios(report);
    reports.push_back(std::move(report));
  }
  if (json) lt::PrintJson(header, reports);
  return ReportStarvedStreams(reports);
}
