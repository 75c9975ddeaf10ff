#include "server/metrics_exposition.h"

#include <filesystem>
#include <system_error>

#include "absl/strings/ascii.h"
#include "absl/strings/string_view.h"
#include "core/public/cpu_baseline.h"
#include "server/observability/process_memory.h"
#include "server/observability/prometheus_text.h"
#include "server/observability/version.h"

namespace nupmpc::server {
namespace {

// "SOLVE_STATUS_CONVERGED" → "converged", "ALGORITHM_IBFFD" → "ibffd".
std::string LowerSuffix(absl::string_view enum_name, absl::string_view prefix) {
  if (enum_name.substr(0, prefix.size()) == prefix) enum_name.remove_prefix(prefix.size());
  return absl::AsciiStrToLower(enum_name);
}

double OpenFileDescriptors() {
  std::error_code error;
  std::filesystem::directory_iterator it("/proc/self/fd", error);
  if (error) return 0.0;
  double n = 0.0;
  for (; it != std::filesystem::directory_iterator(); it.increment(error)) {
    if (error) break;
    ++n;
  }
  return n;
}

void WriteHistogram(PrometheusText& out, absl::string_view name, absl::string_view help, const Histogram& h) {
  out.Family(name, "histogram", help);
  out.Histogram(name, {}, h.upper_bounds(), h.counts(), h.sum());
}

void WriteSolves(PrometheusText& out, const Metrics& m) {
  out.Family("nupmpc_solves_total", "counter", "Solves answered with a result, by status and algorithm.");
  for (int s = 1; s < Metrics::kStatusCount; ++s) {
    const auto status = static_cast<v1::SolveStatus>(s);
    if (status == v1::SOLVE_STATUS_SUPERSEDED) continue;  // answered without a solve
    for (int a = 1; a < Metrics::kAlgorithmCount; ++a) {
      const auto algorithm = static_cast<v1::Algorithm>(a);
      out.Sample("nupmpc_solves_total",
                 {{"status", LowerSuffix(v1::SolveStatus_Name(status), "SOLVE_STATUS_")},
                  {"algorithm", LowerSuffix(v1::Algorithm_Name(algorithm), "ALGORITHM_")}},
                 static_cast<double>(m.solves(status, algorithm)));
    }
  }
}

void WriteErrors(PrometheusText& out, const Metrics& m) {
  out.Family("nupmpc_rpc_errors_total", "counter",
             "RPCs (or Control stream messages) answered with an error, by method and code.");
  for (int r = 0; r < kRpcCount; ++r) {
    for (int c = 1; c < Metrics::kCodeCount; ++c) {
      const std::uint64_t n = m.errors(static_cast<Rpc>(r), static_cast<absl::StatusCode>(c));
      if (n == 0) continue;  // at most 9 × 16 series, written once they exist
      out.Sample("nupmpc_rpc_errors_total",
                 {{"method", std::string(RpcName(static_cast<Rpc>(r)))},
                  {"code", absl::StatusCodeToString(static_cast<absl::StatusCode>(c))}},
                 static_cast<double>(n));
    }
  }
}

void Gauge(PrometheusText& out, absl::string_view name, absl::string_view help, double value) {
  out.Family(name, "gauge", help);
  out.Sample(name, {}, value);
}

void Counter(PrometheusText& out, absl::string_view name, absl::string_view help, double value) {
  out.Family(name, "counter", help);
  out.Sample(name, {}, value);
}

}  // namespace

std::string RenderPrometheusMetrics(const ServerState& state) {
  PrometheusText out;
  const Metrics& m = state.metrics;
  WriteSolves(out, m);
  WriteHistogram(out, "nupmpc_solve_duration_seconds", "Time inside the solver per solve.", m.solve_seconds());
  WriteHistogram(out, "nupmpc_queue_wait_seconds", "Time a solve waited for a worker.", m.queue_wait_seconds());
  WriteHistogram(out, "nupmpc_step_latency_seconds", "From a solve's arrival at the server to its answer.",
                 m.latency_seconds());
  WriteHistogram(out, "nupmpc_solve_iterations", "Message-passing passes per solve.", m.iterations());
  out.Family("nupmpc_step_deadlines_total", "counter",
             "Steps with a deadline (Step.budget_ms or the session's Timing.period_ms), by outcome: met, "
             "queued_past_deadline (answered without a plan, or solved late), solve_too_long.");
  for (int o = 1; o < Metrics::kDeadlineOutcomeCount; ++o) {
    const auto outcome = static_cast<v1::DeadlineOutcome>(o);
    out.Sample("nupmpc_step_deadlines_total",
               {{"outcome", LowerSuffix(v1::DeadlineOutcome_Name(outcome), "DEADLINE_OUTCOME_")}},
               static_cast<double>(m.deadlines(outcome)));
  }
  WriteHistogram(out, "nupmpc_step_deadline_slack_seconds",
                 "Time from a step's answer to its deadline (negative: after it).", m.deadline_slack_seconds());
  WriteErrors(out, m);

  const SessionRegistry& sessions = state.registry;
  Gauge(out, "nupmpc_active_sessions", "Open sessions.", sessions.size());
  Counter(out, "nupmpc_sessions_created_total", "Sessions created.", static_cast<double>(sessions.created_total()));
  Counter(out, "nupmpc_sessions_closed_total", "Sessions closed (by the client, with their stream, or expired).",
          static_cast<double>(sessions.closed_total()));
  Counter(out, "nupmpc_sessions_expired_total", "Sessions closed after --session_idle_timeout_s without use.",
          static_cast<double>(sessions.expired_total()));
  Counter(out, "nupmpc_sessions_compacted_total", "Idle sessions that gave their solver scratch memory back.",
          static_cast<double>(sessions.compacted_total()));
  Gauge(out, "nupmpc_control_streams", "Open Control streams.", state.control_streams.load());
  Counter(out, "nupmpc_auth_refused_total",
          "Calls refused with UNAUTHENTICATED before reaching the service (missing or unknown token or certificate).",
          state.auth != nullptr ? static_cast<double>(state.auth->refused_total()) : 0.0);
  out.Family("nupmpc_control_stream_ends_total", "counter",
             "Control streams ended, by cause: client_closed (half-close), client_gone (cancelled or reset while the "
             "client was active), keepalive (cancelled after the client was silent past --keepalive_timeout_s: a "
             "vanished client found by keepalive pings, by this rule of thumb), server_ended (an error).");
  for (int e = 0; e < kStreamEndCount; ++e) {
    const auto end = static_cast<StreamEnd>(e);
    out.Sample("nupmpc_control_stream_ends_total", {{"cause", std::string(StreamEndName(end))}},
               static_cast<double>(state.stream_ends.count(end)));
  }
  Counter(out, "nupmpc_client_held_periods_total",
          "Control periods clients held without an answer in time, as they reported them with their next step.",
          static_cast<double>(state.client_held_periods.load()));
  out.Family("nupmpc_session_snapshots_total", "counter",
             "Session snapshots (--state_dir): written on SIGTERM, restored when their client re-attached, failed "
             "(claimed but not restorable: the client re-creates the session cold).");
  for (const auto& [event, count] : {std::pair<const char*, std::uint64_t>{"written", state.snapshots_written.load()},
                                     {"restored", state.snapshots_restored.load()},
                                     {"failed", state.snapshots_failed.load()}}) {
    out.Sample("nupmpc_session_snapshots_total", {{"event", event}}, static_cast<double>(count));
  }
  Counter(out, "nupmpc_control_stream_read_pauses_total",
          "Times a Control stream stopped reading because its client left answers unread.",
          static_cast<double>(state.stream_read_pauses.load()));

  const WorkerPool& pool = state.pool;
  Gauge(out, "nupmpc_queue_depth", "Solves and other work waiting for a worker.", pool.queued());
  Gauge(out, "nupmpc_workers", "Solver worker threads.", pool.threads());
  Gauge(out, "nupmpc_solver_cores", "Solves that may run at once (workers and gRPC threads solving in place).",
        pool.cores());
  Gauge(out, "nupmpc_workers_busy", "Cores running a task now (on a worker or solved where it arrived).", pool.busy());
  Counter(out, "nupmpc_worker_busy_seconds_total",
          "Seconds the cores spent running tasks; its rate over nupmpc_solver_cores is the pool's utilisation.",
          pool.busy_seconds());
  Counter(out, "nupmpc_solves_in_place_total",
          "Control steps solved on the gRPC thread that received them (short solves, or ones a hand-off would make "
          "late; a core free).",
          static_cast<double>(pool.run_here()));
  Gauge(out, "nupmpc_worker_handoff_seconds",
        "What handing a solve to an idle worker costs here (weighted average; 0 until measured).",
        pool.handoff_ms() / 1000.0);

  Gauge(out, "nupmpc_memory_budget_bytes", "The memory budget sessions and calls reserve in.",
        static_cast<double>(state.budget.capacity()));
  Gauge(out, "nupmpc_memory_reserved_bytes", "The budget reserved now, by estimate.",
        static_cast<double>(state.budget.reserved()));
  Gauge(out, "nupmpc_process_resident_memory_bytes", "Resident set size of the server process.",
        static_cast<double>(ResidentMemoryBytes()));
  Gauge(out, "nupmpc_process_open_fds", "Open file descriptors of the server process.", OpenFileDescriptors());
  Gauge(out, "nupmpc_draining", "1 once the server stopped reporting SERVING (SIGTERM), else 0.",
        state.serving.load() ? 0.0 : 1.0);

  out.Family("nupmpc_build_info", "gauge", "Always 1; the labels describe the build.");
  out.Sample("nupmpc_build_info",
             {{"version", kVersion}, {"api_version", "nupmpc.v1"}, {"cpu_baseline", platform::kBuildCpuBaseline}}, 1.0);
  return out.text();
}

}  // namespace nupmpc::server
