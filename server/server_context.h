#ifndef NUPMPC_SERVER_SERVER_CONTEXT_H_
#define NUPMPC_SERVER_SERVER_CONTEXT_H_

#include <algorithm>
#include <atomic>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "grpcpp/server_context.h"
#include "grpcpp/support/status.h"
#include "server/auth_processor.h"
#include "server/gp_model_cache.h"
#include "server/memory_budget.h"
#include "server/metrics.h"
#include "server/principal_streams.h"
#include "server/session_registry.h"
#include "server/spec_conversion.h"
#include "server/token_file.h"
#include "server/transport_security.h"
#include "server/worker_pool.h"

namespace nupmpc::server {

struct ServerOptions {
  std::string address = "[::]:50051";
  int worker_threads = 2;
  // Control steps of sessions whose last solve took at most this long are solved on the
  // gRPC thread that received them when a core is free, and that thread runs such steps
  // queued behind it for up to this long (ControlStream::StartSolve); 0: never.
  double inline_solve_max_ms = 0.5;
  int max_fleet_steps = 10000;  ///< steps in one SolveFleet call
  int queue_capacity = 64;
  double max_queue_wait_ms = 0.0;  ///< 0: only queue_capacity bounds the queue
  int max_sessions = 10000;
  double session_idle_timeout_s = 600.0;
  double session_compact_idle_s = 10.0;  ///< 0: idle sessions keep their scratch
  int max_message_bytes = 64 << 20;
  double grace_period_s = 5.0;
  std::int64_t memory_budget_bytes = 0;  ///< 0: DefaultMemoryBudgetBytes()
  int max_control_streams = 1000;         ///< open Control streams, server-wide
  int max_stream_answers = 16;            ///< answers a Control stream queues before it stops reading
  int max_streams_per_connection = 100;   ///< HTTP/2 concurrent streams (calls) per client connection
  double first_message_timeout_s = 10.0;  ///< a connection's handshake and a Control stream's first message
  double connection_idle_timeout_s = 600.0;  ///< a connection without calls this long is closed
  std::string metrics_address;            ///< HTTP /metrics, /healthz, /readyz; empty: none
  TlsFiles tls;                           ///< TLS / mTLS of the gRPC port; none by default
  std::string auth_tokens_file;           ///< bearer tokens (server/token_file.h); empty: none
  int max_sessions_per_principal = 0;     ///< 0: only max_sessions
  int max_streams_per_principal = 0;      ///< 0: only max_control_streams
  bool list_all_sessions = false;         ///< without authentication: ListSessions shows every connection's
  double slow_solve_ms = 0.0;             ///< solves slower than this are logged at warn; 0: none
  SizeLimits size_limits;
};

// gRPC's callback API runs its reactions on at least two threads whatever the machine
// (gRPC 1.51, src/cpp/common/completion_queue_cc.cc: max(2, CPUs / 2), at most 16).
inline constexpr int kGrpcReactionThreadsAtLeast = 2;

// Solves that may run at once: --threads, and with solves on gRPC's threads at least as many
// as gRPC has threads taking requests. A server given one core (--threads 1) has two
// reaction threads sharing it anyway; allowing a short step to be solved only on one of
// them hands every step that arrives during a solve to the other (two thread switches per
// step: more than the transport costs a masses_N30 step), where letting both solve costs
// the scheduler a switch every time slice.
inline int SolverCores(const ServerOptions& o) {
  return o.inline_solve_max_ms > 0.0 ? std::max(o.worker_threads, kGrpcReactionThreadsAtLeast) : o.worker_threads;
}

// What every RPC handler shares: options, sessions, the solver pool, counters, and the
// draining flag (set on SIGTERM: new work is refused with UNAVAILABLE).
struct ServerState {
  explicit ServerState(const ServerOptions& o)
      : options(o),
        budget(o.memory_budget_bytes > 0 ? o.memory_budget_bytes : DefaultMemoryBudgetBytes()),
        registry(o.max_sessions, pool, o.max_sessions_per_principal),  // only kept: the pool is built next, and joined first
        pool(o.worker_threads, o.queue_capacity, o.max_queue_wait_ms, SolverCores(o)),
        principal_streams(o.max_streams_per_principal) {}
  ServerOptions options;
  MemoryBudget budget;  ///< before the registry: sessions give their reservations back to it
  SessionRegistry registry;
  WorkerPool pool;
  Metrics metrics;
  PrincipalStreams principal_streams;
  std::shared_ptr<TokenStore> tokens;  ///< --auth_tokens_file (null: none), re-read by the janitor
  std::shared_ptr<AuthProcessor> auth;  ///< null: authentication off
  GpModelCache gp_models;  ///< factorised GP models shared by the sessions that use them
  // From SIGTERM on (the drain delay included): what grpc.health.v1 (NOT_SERVING),
  // nupmpc_draining and GetServerInfo.draining report, one truth for the three.
  std::atomic<bool> serving{true};
  // After the drain delay: new calls, streams and steps are refused with UNAVAILABLE.
  std::atomic<bool> draining{false};
  // Unary calls not yet answered and Control streams with a step being solved: the work a
  // shutdown lets finish before it ends what is left (idle connections and streams).
  std::atomic<int> work_in_flight{0};
  std::atomic<int> control_streams{0};  ///< open Control streams
  std::atomic<std::uint64_t> stream_read_pauses{0};  ///< times a stream stopped reading (flow control)

  // An absl::Status of `rpc` as a gRPC status, counted when it is an error.
  grpc::Status ToGrpc(Rpc rpc, const absl::Status& status);
  // A finished solve: its metrics, and a warning when it took longer than slow_solve_ms
  // (`session`: null for SolveOnce).
  void RecordSolve(const v1::SolveResult& result, const SessionEntry* session, double queue_wait_s, double latency_s);
  void FillLimits(v1::ServerLimits* out) const;
};

// The call's deadline on the steady clock the solver measures (none if the client set none).
std::optional<Clock::time_point> SteadyDeadline(const grpc::CallbackServerContext& context);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SERVER_CONTEXT_H_
