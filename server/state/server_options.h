#ifndef NUPMPC_SERVER_STATE_SERVER_OPTIONS_H_
#define NUPMPC_SERVER_STATE_SERVER_OPTIONS_H_

// What the process is told (flags, environment, tests' ServerOptions): the service's limits,
// addresses and security, one struct every part reads and nobody writes after start-up.

#include <algorithm>
#include <cstdint>
#include <string>

#include "server/auth/transport_security.h"
#include "server/convert/spec_conversion.h"
#include "server/scheduling/worker_pool.h"

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
  // The order in which waiting steps are taken: earliest deadline first, or arrival.
  WorkerPool::Scheduling scheduling = WorkerPool::Scheduling::kEarliestDeadlineFirst;
  double max_queue_wait_ms = 0.0;  ///< 0: only queue_capacity bounds the queue
  int max_sessions = 10000;
  double session_idle_timeout_s = 600.0;
  double session_compact_idle_s = 10.0;  ///< 0: idle sessions keep their scratch
  int max_message_bytes = 64 << 20;
  double grace_period_s = 5.0;
  std::int64_t memory_budget_bytes = 0;      ///< 0: DefaultMemoryBudgetBytes()
  int max_control_streams = 1000;            ///< open Control streams, server-wide
  int max_stream_answers = 16;               ///< answers a Control stream queues before it stops reading
  int max_streams_per_connection = 100;      ///< HTTP/2 concurrent streams (calls) per client connection
  double first_message_timeout_s = 10.0;     ///< a connection's handshake and a Control stream's first message
  double connection_idle_timeout_s = 600.0;  ///< a connection without calls this long is closed
  // HTTP/2 keepalive of connections with calls open: a ping after keepalive_time_s without
  // a frame from the client, the connection closed when it is not answered within
  // keepalive_timeout_s. A peer that vanished without a word is found within their sum.
  double keepalive_time_s = 5.0;
  double keepalive_timeout_s = 5.0;
  std::string metrics_address;         ///< HTTP /metrics, /healthz, /readyz; empty: none
  TlsFiles tls;                        ///< TLS / mTLS of the gRPC port; none by default
  std::string auth_tokens_file;        ///< bearer tokens (server/auth/token_file.h); empty: none
  int max_sessions_per_principal = 0;  ///< 0: only max_sessions
  int max_streams_per_principal = 0;   ///< 0: only max_control_streams
  bool list_all_sessions = false;      ///< without authentication: ListSessions shows every connection's
  double slow_solve_ms = 0.0;          ///< solves slower than this are logged at warn; 0: none
  // Session snapshots (server/snapshots/): written here on SIGTERM, claimed by the server a
  // session's client comes back to within reattach_window_s; empty: none (sessions end
  // with the process).
  std::string state_dir;
  std::string snapshot_key_file;  ///< the replicas' shared key; empty: SHA-256 checksums only
  double reattach_window_s = 300.0;
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

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_STATE_SERVER_OPTIONS_H_
