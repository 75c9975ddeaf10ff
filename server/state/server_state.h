#ifndef NUPMPC_SERVER_STATE_SERVER_STATE_H_
#define NUPMPC_SERVER_STATE_SERVER_STATE_H_

#include <algorithm>
#include <atomic>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "grpcpp/server_context.h"
#include "grpcpp/support/status.h"
#include "server/auth/auth_processor.h"
#include "server/auth/principal_streams.h"
#include "server/auth/token_file.h"
#include "server/auth/transport_security.h"
#include "server/convert/gp_model_cache.h"
#include "server/convert/spec_conversion.h"
#include "server/observability/metrics.h"
#include "server/observability/stream_ends.h"
#include "server/scheduling/worker_pool.h"
#include "server/sessions/memory_budget.h"
#include "server/sessions/session_registry.h"
#include "server/snapshots/snapshot_store.h"
#include "server/state/server_options.h"

namespace nupmpc::server {

// What every RPC handler shares: options, sessions, the solver pool, counters, and the
// draining flag (set on SIGTERM: new work is refused with UNAVAILABLE).
struct ServerState {
  explicit ServerState(const ServerOptions& o)
      : options(o),
        budget(o.memory_budget_bytes > 0 ? o.memory_budget_bytes : DefaultMemoryBudgetBytes()),
        registry(o.max_sessions, pool,
                 o.max_sessions_per_principal),  // only kept: the pool is built next, and joined first
        pool(o.worker_threads, o.queue_capacity, o.max_queue_wait_ms, SolverCores(o), o.scheduling),
        principal_streams(o.max_streams_per_principal) {}
  ServerOptions options;
  MemoryBudget budget;  ///< before the registry: sessions give their reservations back to it
  SessionRegistry registry;
  WorkerPool pool;
  Metrics metrics;
  PrincipalStreams principal_streams;
  std::shared_ptr<TokenStore> tokens;        ///< --auth_tokens_file (null: none), re-read by the janitor
  std::shared_ptr<AuthProcessor> auth;       ///< null: authentication off
  GpModelCache gp_models;                    ///< factorised GP models shared by the sessions that use them
  std::unique_ptr<SnapshotStore> snapshots;  ///< --state_dir (null: none)
  // From SIGTERM on (the drain delay included): what grpc.health.v1 (NOT_SERVING),
  // nupmpc_draining and GetServerInfo.draining report, one truth for the three.
  std::atomic<bool> serving{true};
  // After the drain delay: new calls, streams and steps are refused with UNAVAILABLE.
  std::atomic<bool> draining{false};
  // Unary calls not yet answered and Control streams with a step being solved: the work a
  // shutdown lets finish before it ends what is left (idle connections and streams).
  std::atomic<int> work_in_flight{0};
  std::atomic<int> control_streams{0};               ///< open Control streams
  std::atomic<std::uint64_t> stream_read_pauses{0};  ///< times a stream stopped reading (flow control)
  StreamEnds stream_ends;                            ///< why Control streams ended
  /// Periods Control clients held without an answer in time, as they report them
  /// (ControlRequest.held_periods).
  std::atomic<std::uint64_t> client_held_periods{0};
  // Session snapshots (--state_dir): written on SIGTERM, restored when their clients came
  // back, and claimed but not restorable (their clients re-create them cold).
  std::atomic<std::uint64_t> snapshots_written{0};
  std::atomic<std::uint64_t> snapshots_restored{0};
  std::atomic<std::uint64_t> snapshots_failed{0};

  // An absl::Status of `rpc` as a gRPC status, counted when it is an error.
  grpc::Status ToGrpc(Rpc rpc, const absl::Status& status);
  // A finished solve: its metrics, and a warning when it took longer than slow_solve_ms
  // (`session`: null for SolveOnce).
  void RecordSolve(const v1::SolveResult& result, const SessionEntry* session, double queue_wait_s, double latency_s);
  void FillLimits(v1::ServerLimits* out) const;

  // The session `id` for `caller`: the registry's, or, when the server has a state
  // directory holding its snapshot, that snapshot restored and registered (the work of
  // creating the session: not on gRPC's threads). NOT_FOUND as Find otherwise.
  // `by_control_stream`: a Control stream's attach (only it restores a stream-owned session).
  absl::StatusOr<std::shared_ptr<SessionEntry>> FindOrRestore(const std::string& id, const Caller& caller,
                                                              bool by_control_stream);
  // Whether FindOrRestore may have to restore (the registry does not hold `id`).
  bool MayRestore(const std::string& id, const Caller& caller) const;
  // Every session's snapshot, written to the state directory (on SIGTERM, once the work in
  // flight is done), each right after the task its strand may still run; waits until all
  // are written or `until`, and returns how many were written by then.
  int WriteSnapshots(Clock::time_point until);
};

// The call's deadline on the steady clock the solver measures (none if the client set none).
std::optional<Clock::time_point> SteadyDeadline(const grpc::CallbackServerContext& context);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_STATE_SERVER_STATE_H_
