#include "server/server_flags.h"

#include <cstdlib>

#include "absl/flags/flag.h"
#include "absl/flags/reflection.h"
#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "cli/program_flags.h"
#include "spdlog/common.h"

ABSL_FLAG(std::string, address, "[::]:50051", "listen address host:port (env NUPMPC_ADDRESS)");
ABSL_FLAG(int, threads, 2,
          "solver worker threads; solves at once: this many, or 2 if fewer and steps are solved on gRPC's threads "
          "(env NUPMPC_THREADS)");
ABSL_FLAG(
    double, inline_solve_max_ms, 0.5,
    "a Control step is solved on the gRPC thread that received it (no hand-off to a worker) when its "
    "session's last solve took at most this long (CPU time) and a core is free (that thread also runs such steps "
    "queued behind it, for up to this long), or took up to 10 times this long and the step meets its deadline only "
    "without the hand-off; 0: always on a worker "
    "(env NUPMPC_INLINE_SOLVE_MAX_MS)");
ABSL_FLAG(int, max_fleet_steps, 10000, "steps in one SolveFleet call (env NUPMPC_MAX_FLEET_STEPS)");
ABSL_FLAG(int, queue_capacity, 64, "solves waiting for a worker before RESOURCE_EXHAUSTED (env NUPMPC_QUEUE_CAPACITY)");
ABSL_FLAG(std::string, scheduling, "edf",
          "the order waiting steps are solved in: edf (earliest deadline first; work without a deadline counts as due "
          "1 s after it arrived) or fifo (arrival) (env NUPMPC_SCHEDULING)");
ABSL_FLAG(int, max_sessions, 10000, "maximum open sessions (env NUPMPC_MAX_SESSIONS)");
ABSL_FLAG(double, session_idle_timeout_s, 600, "close sessions idle this long (env NUPMPC_SESSION_IDLE_TIMEOUT_S)");
ABSL_FLAG(double, max_queue_wait_ms, 0,
          "refuse work the queued solves would delay longer than this; 0: only --queue_capacity "
          "(env NUPMPC_MAX_QUEUE_WAIT_MS)");
ABSL_FLAG(double, session_compact_idle_s, 10,
          "sessions idle this long free their solver scratch memory; 0: never (env NUPMPC_SESSION_COMPACT_IDLE_S)");
ABSL_FLAG(int, max_message_bytes, 64 << 20, "largest request/response (env NUPMPC_MAX_MESSAGE_BYTES)");
ABSL_FLAG(int, max_horizon, 100000, "largest horizon N (env NUPMPC_MAX_HORIZON)");
ABSL_FLAG(int, max_states, 1000, "largest state dimension (env NUPMPC_MAX_STATES)");
ABSL_FLAG(int, max_iterations, 100000, "largest per-solve iteration cap (env NUPMPC_MAX_ITERATIONS)");
ABSL_FLAG(std::string, state_dir, "",
          "on SIGTERM/SIGINT, write every session's snapshot (spec, current values, warm start) to this directory "
          "(created 0700); a server started on it, or sharing it, restores a session when its client re-attaches by "
          "id; empty: sessions end with the process (env NUPMPC_STATE_DIR)");
ABSL_FLAG(std::string, snapshot_key_file, "",
          "a key (at least 32 bytes, chmod 600) the replicas sharing --state_dir share: snapshots are sealed with "
          "HMAC-SHA256 and any other is refused; empty: a SHA-256 checksum only, for a directory only this server's "
          "user can write (env NUPMPC_SNAPSHOT_KEY_FILE)");
ABSL_FLAG(double, reattach_window_s, 300,
          "a snapshot is restored only this long after it was written; older ones are removed "
          "(env NUPMPC_REATTACH_WINDOW_S)");
ABSL_FLAG(double, grace_period_s, 5, "on SIGTERM/SIGINT: time for in-flight solves (env NUPMPC_GRACE_PERIOD_S)");
ABSL_FLAG(double, drain_delay_s, 0,
          "on SIGTERM/SIGINT: report NOT_SERVING on grpc.health.v1 this long while still serving, so load balancers "
          "move new calls away, before draining; a second signal ends the delay (env NUPMPC_DRAIN_DELAY_S)");
ABSL_FLAG(
    int, memory_budget_mb, 0,
    "memory all sessions and calls in flight may reserve, by estimate, before requests are refused with "
    "RESOURCE_EXHAUSTED; 0: 3/4 of the smaller of physical memory and the cgroup limit (env NUPMPC_MEMORY_BUDGET_MB)");
ABSL_FLAG(int, max_session_memory_mb, 2048,
          "estimated memory one session, SolveOnce or GP fit may need (env NUPMPC_MAX_SESSION_MEMORY_MB)");
ABSL_FLAG(double, max_pass_gflop, 1000,
          "estimated work (GFLOP) of one message-passing pass a session may need (env NUPMPC_MAX_PASS_GFLOP)");
ABSL_FLAG(int, max_control_streams, 1000, "open Control streams, server-wide (env NUPMPC_MAX_CONTROL_STREAMS)");
ABSL_FLAG(int, max_stream_answers, 16,
          "answers a Control stream queues for a client that does not read before it stops reading its steps "
          "(env NUPMPC_MAX_STREAM_ANSWERS)");
ABSL_FLAG(int, max_streams_per_connection, 100,
          "concurrent calls on one client connection (env NUPMPC_MAX_STREAMS_PER_CONNECTION)");
ABSL_FLAG(
    double, first_message_timeout_s, 10,
    "a new connection's handshake and a new Control stream's first message must arrive within this long, "
    "else the connection is closed / the stream ended with DEADLINE_EXCEEDED (env NUPMPC_FIRST_MESSAGE_TIMEOUT_S)");
ABSL_FLAG(double, connection_idle_timeout_s, 600,
          "close client connections without calls for this long (env NUPMPC_CONNECTION_IDLE_TIMEOUT_S)");
ABSL_FLAG(double, keepalive_time_s, 5,
          "ping each client connection with calls open after this long without a frame from it "
          "(env NUPMPC_KEEPALIVE_TIME_S)");
ABSL_FLAG(double, keepalive_timeout_s, 5,
          "close a connection whose ping is not answered within this long, ending its streams: a client that "
          "vanished silently (partition, frozen machine) is found within keepalive_time_s + keepalive_timeout_s "
          "(env NUPMPC_KEEPALIVE_TIMEOUT_S)");
ABSL_FLAG(std::string, metrics_address, "",
          "HTTP endpoint for operators: GET /metrics (Prometheus text), /healthz, /readyz; HOST:PORT or :PORT "
          "(e.g. :9464); empty: off (env NUPMPC_METRICS_ADDRESS)");
ABSL_FLAG(std::string, tls_cert_file, "",
          "PEM certificate chain of the gRPC port; with --tls_key_file: TLS. Re-read when it changes, so rotation "
          "needs no restart (env NUPMPC_TLS_CERT_FILE)");
ABSL_FLAG(std::string, tls_key_file, "", "PEM private key of --tls_cert_file (env NUPMPC_TLS_KEY_FILE)");
ABSL_FLAG(std::string, tls_client_ca_file, "",
          "PEM CA bundle: clients must present a certificate it signed (mTLS); the certificate's subject is the "
          "caller's principal when the call carries no bearer token (env NUPMPC_TLS_CLIENT_CA_FILE)");
ABSL_FLAG(std::string, trusted_balancer_subject, "",
          "subject of the balancer's client certificate as RFC 2253 prints it (e.g. CN=nupmpc-balancer,O=example); "
          "a call from that peer without a bearer token is the caller the balancer verified and named in the "
          "x-nupmpc-client-subject header, and UNAUTHENTICATED without it; from other peers the header is ignored. "
          "Needs --tls_client_ca_file (env NUPMPC_TRUSTED_BALANCER_SUBJECT)");
ABSL_FLAG(int, tls_reload_interval_s, 10,
          "how often the TLS files are checked for changes (env NUPMPC_TLS_RELOAD_INTERVAL_S)");
ABSL_FLAG(std::string, auth_tokens_file, "",
          "bearer tokens: one line per token, TOKEN PRINCIPAL [admin], # comments; calls must send "
          "'authorization: Bearer TOKEN'; sessions belong to their creator's principal; re-read when it changes. "
          "Needs TLS unless the address is loopback or a Unix socket (env NUPMPC_AUTH_TOKENS_FILE)");
ABSL_FLAG(
    int, max_sessions_per_principal, 0,
    "sessions one authenticated principal may hold; 0: only --max_sessions (env NUPMPC_MAX_SESSIONS_PER_PRINCIPAL)");
ABSL_FLAG(int, max_streams_per_principal, 0,
          "Control streams one authenticated principal may have open; 0: only --max_control_streams "
          "(env NUPMPC_MAX_STREAMS_PER_PRINCIPAL)");
ABSL_FLAG(bool, list_all_sessions, false,
          "without authentication: ListSessions shows the sessions of every connection, not only the caller's "
          "(env NUPMPC_LIST_ALL_SESSIONS)");
ABSL_FLAG(double, slow_solve_ms, 0,
          "solves slower than this are logged at warn with their dimensions and iterations; 0: none "
          "(env NUPMPC_SLOW_SOLVE_MS)");
ABSL_FLAG(std::string, log_format, "text",
          "text|json: one JSON object per line for log collectors (env NUPMPC_LOG_FORMAT)");
ABSL_FLAG(std::string, log_level, "info", "trace|debug|info|warn|error|off (env NUPMPC_LOG_LEVEL)");

namespace nupmpc::server {
namespace {

// Sets a flag from its environment variable; the command line, parsed afterwards, wins.
absl::Status ApplyEnvironment(const char* name) {
  absl::CommandLineFlag* flag = absl::FindCommandLineFlag(name);
  if (flag == nullptr) return absl::OkStatus();
  const std::string variable = absl::StrCat("NUPMPC_", absl::AsciiStrToUpper(name));
  const char* value = std::getenv(variable.c_str());
  if (value == nullptr) return absl::OkStatus();
  std::string error;
  if (!flag->ParseFrom(value, &error)) {
    return absl::InvalidArgumentError(absl::StrCat(variable, "=", value, ": ", error));
  }
  return absl::OkStatus();
}

// Written as !(value >= bound) so that NaN is refused too.
template <typename T>
absl::Status RequireAtLeast(const char* name, T value, T minimum) {
  if (!(value >= minimum))
    return absl::InvalidArgumentError(absl::StrCat("--", name, " = ", value, ": must be >= ", minimum));
  return absl::OkStatus();
}
template <typename T>
absl::Status RequireAtMost(const char* name, T value, T maximum) {
  if (!(value <= maximum))
    return absl::InvalidArgumentError(absl::StrCat("--", name, " = ", value, ": must be <= ", maximum));
  return absl::OkStatus();
}

}  // namespace

const cli::ProgramInfo& ServerProgram() {
  static const cli::ProgramInfo program{
      .name = "nupmpc-server",
      .summary =
          "nupmpc-server: model-predictive control over gRPC (nupmpc.v1.MpcService: sessions, the "
          "Control stream, one-off solves, GP fits), with grpc.health.v1 and server reflection. "
          "SIGTERM/SIGINT drain (in-flight solves get --grace_period_s) and exit 0.",
      .usage = "nupmpc-server [--address HOST:PORT] [--threads N] [FLAGS]",
      .environment = {{"NUPMPC_<FLAG>",
                       "every flag above, its name in upper case (NUPMPC_ADDRESS, NUPMPC_THREADS, ...): the "
                       "value used when the flag is not on the command line"}},
      .max_arguments = 0,
  };
  return program;
}

absl::StatusOr<ParsedFlags> ParseServerFlags(int argc, char** argv) {
  for (const char* name : {"address",
                           "threads",
                           "inline_solve_max_ms",
                           "max_fleet_steps",
                           "queue_capacity",
                           "max_sessions",
                           "session_idle_timeout_s",
                           "session_compact_idle_s",
                           "max_queue_wait_ms",
                           "max_message_bytes",
                           "max_horizon",
                           "max_states",
                           "max_iterations",
                           "grace_period_s",
                           "drain_delay_s",
                           "state_dir",
                           "snapshot_key_file",
                           "reattach_window_s",
                           "memory_budget_mb",
                           "max_session_memory_mb",
                           "max_pass_gflop",
                           "max_control_streams",
                           "max_stream_answers",
                           "max_streams_per_connection",
                           "first_message_timeout_s",
                           "connection_idle_timeout_s",
                           "keepalive_time_s",
                           "keepalive_timeout_s",
                           "metrics_address",
                           "tls_cert_file",
                           "tls_key_file",
                           "tls_client_ca_file",
                           "tls_reload_interval_s",
                           "trusted_balancer_subject",
                           "auth_tokens_file",
                           "max_sessions_per_principal",
                           "max_streams_per_principal",
                           "list_all_sessions",
                           "slow_solve_ms",
                           "log_format",
                           "log_level",
                           "scheduling"}) {
    if (absl::Status s = ApplyEnvironment(name); !s.ok()) return s;
  }
  cli::ParseProgramFlags(ServerProgram(), argc, argv);
  ParsedFlags out;
  ServerOptions& o = out.options;
  o.address = absl::GetFlag(FLAGS_address);
  o.worker_threads = absl::GetFlag(FLAGS_threads);
  o.inline_solve_max_ms = absl::GetFlag(FLAGS_inline_solve_max_ms);
  o.max_fleet_steps = absl::GetFlag(FLAGS_max_fleet_steps);
  o.queue_capacity = absl::GetFlag(FLAGS_queue_capacity);
  if (const std::string scheduling = absl::GetFlag(FLAGS_scheduling); scheduling == "fifo") {
    o.scheduling = WorkerPool::Scheduling::kFifo;
  } else if (scheduling != "edf") {
    return absl::InvalidArgumentError(absl::StrCat("--scheduling = ", scheduling, ": must be edf or fifo"));
  }
  o.max_sessions = absl::GetFlag(FLAGS_max_sessions);
  o.session_idle_timeout_s = absl::GetFlag(FLAGS_session_idle_timeout_s);
  o.session_compact_idle_s = absl::GetFlag(FLAGS_session_compact_idle_s);
  o.max_queue_wait_ms = absl::GetFlag(FLAGS_max_queue_wait_ms);
  o.max_message_bytes = absl::GetFlag(FLAGS_max_message_bytes);
  o.size_limits.max_horizon = absl::GetFlag(FLAGS_max_horizon);
  o.size_limits.max_states = absl::GetFlag(FLAGS_max_states);
  o.size_limits.max_iterations = absl::GetFlag(FLAGS_max_iterations);
  o.grace_period_s = absl::GetFlag(FLAGS_grace_period_s);
  o.memory_budget_bytes = static_cast<std::int64_t>(absl::GetFlag(FLAGS_memory_budget_mb)) << 20;
  o.size_limits.max_session_bytes = static_cast<long long>(absl::GetFlag(FLAGS_max_session_memory_mb)) << 20;
  o.size_limits.max_pass_flops = absl::GetFlag(FLAGS_max_pass_gflop) * 1e9;
  o.max_control_streams = absl::GetFlag(FLAGS_max_control_streams);
  o.max_stream_answers = absl::GetFlag(FLAGS_max_stream_answers);
  o.max_streams_per_connection = absl::GetFlag(FLAGS_max_streams_per_connection);
  o.first_message_timeout_s = absl::GetFlag(FLAGS_first_message_timeout_s);
  o.connection_idle_timeout_s = absl::GetFlag(FLAGS_connection_idle_timeout_s);
  o.keepalive_time_s = absl::GetFlag(FLAGS_keepalive_time_s);
  o.keepalive_timeout_s = absl::GetFlag(FLAGS_keepalive_timeout_s);
  o.metrics_address = absl::GetFlag(FLAGS_metrics_address);
  o.tls.cert_file = absl::GetFlag(FLAGS_tls_cert_file);
  o.tls.key_file = absl::GetFlag(FLAGS_tls_key_file);
  o.tls.client_ca_file = absl::GetFlag(FLAGS_tls_client_ca_file);
  o.tls.reload_interval_s = absl::GetFlag(FLAGS_tls_reload_interval_s);
  o.tls.trusted_balancer_subject = absl::GetFlag(FLAGS_trusted_balancer_subject);
  o.auth_tokens_file = absl::GetFlag(FLAGS_auth_tokens_file);
  o.max_sessions_per_principal = absl::GetFlag(FLAGS_max_sessions_per_principal);
  o.max_streams_per_principal = absl::GetFlag(FLAGS_max_streams_per_principal);
  o.list_all_sessions = absl::GetFlag(FLAGS_list_all_sessions);
  o.slow_solve_ms = absl::GetFlag(FLAGS_slow_solve_ms);
  o.state_dir = absl::GetFlag(FLAGS_state_dir);
  o.snapshot_key_file = absl::GetFlag(FLAGS_snapshot_key_file);
  o.reattach_window_s = absl::GetFlag(FLAGS_reattach_window_s);
  out.log_level = absl::GetFlag(FLAGS_log_level);
  out.log_format = absl::GetFlag(FLAGS_log_format);
  if (spdlog::level::from_str(out.log_level) == spdlog::level::off && out.log_level != "off") {
    return absl::InvalidArgumentError(
        absl::StrCat("--log_level = ", out.log_level, ": must be trace, debug, info, warn, error or off"));
  }
  if (out.log_format != "text" && out.log_format != "json") {
    return absl::InvalidArgumentError(absl::StrCat("--log_format = ", out.log_format, ": must be text or json"));
  }
  out.drain_delay_s = absl::GetFlag(FLAGS_drain_delay_s);
  for (const absl::Status& s : {RequireAtLeast("threads", o.worker_threads, 1),
                                RequireAtLeast("queue_capacity", o.queue_capacity, 1),
                                RequireAtLeast("max_sessions", o.max_sessions, 1),
                                RequireAtLeast("session_idle_timeout_s", o.session_idle_timeout_s, 0.001),
                                RequireAtLeast("max_message_bytes", o.max_message_bytes, 1024),
                                RequireAtLeast("max_horizon", o.size_limits.max_horizon, 1),
                                RequireAtLeast("max_states", o.size_limits.max_states, 1),
                                RequireAtLeast("max_iterations", o.size_limits.max_iterations, 1),
                                RequireAtLeast("grace_period_s", o.grace_period_s, 0.0),
                                RequireAtLeast("drain_delay_s", out.drain_delay_s, 0.0),
                                RequireAtLeast("reattach_window_s", o.reattach_window_s, 0.0),
                                RequireAtMost("drain_delay_s", out.drain_delay_s, 3600.0),
                                RequireAtLeast("session_compact_idle_s", o.session_compact_idle_s, 0.0),
                                RequireAtLeast("max_queue_wait_ms", o.max_queue_wait_ms, 0.0),
                                RequireAtLeast("inline_solve_max_ms", o.inline_solve_max_ms, 0.0),
                                RequireAtMost("inline_solve_max_ms", o.inline_solve_max_ms, 1000.0),
                                RequireAtLeast("max_fleet_steps", o.max_fleet_steps, 1),
                                RequireAtLeast("memory_budget_mb", absl::GetFlag(FLAGS_memory_budget_mb), 0),
                                RequireAtLeast("max_session_memory_mb", absl::GetFlag(FLAGS_max_session_memory_mb), 1),
                                RequireAtLeast("max_pass_gflop", absl::GetFlag(FLAGS_max_pass_gflop), 1e-6),
                                RequireAtLeast("max_control_streams", o.max_control_streams, 1),
                                RequireAtLeast("max_stream_answers", o.max_stream_answers, 2),
                                RequireAtLeast("max_streams_per_connection", o.max_streams_per_connection, 1),
                                RequireAtLeast("first_message_timeout_s", o.first_message_timeout_s, 0.001),
                                RequireAtMost("first_message_timeout_s", o.first_message_timeout_s, 86400.0),
                                RequireAtLeast("connection_idle_timeout_s", o.connection_idle_timeout_s, 0.001),
                                RequireAtMost("connection_idle_timeout_s", o.connection_idle_timeout_s, 1e9),
                                RequireAtLeast("keepalive_time_s", o.keepalive_time_s, 0.1),
                                RequireAtMost("keepalive_time_s", o.keepalive_time_s, 86400.0),
                                RequireAtLeast("keepalive_timeout_s", o.keepalive_timeout_s, 0.1),
                                RequireAtMost("keepalive_timeout_s", o.keepalive_timeout_s, 86400.0),
                                RequireAtLeast("tls_reload_interval_s", o.tls.reload_interval_s, 1),
                                RequireAtLeast("max_sessions_per_principal", o.max_sessions_per_principal, 0),
                                RequireAtLeast("max_streams_per_principal", o.max_streams_per_principal, 0),
                                RequireAtLeast("slow_solve_ms", o.slow_solve_ms, 0.0)}) {
    if (!s.ok()) return s;
  }
  return out;
}

}  // namespace nupmpc::server
