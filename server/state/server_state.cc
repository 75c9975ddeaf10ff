#include "server/state/server_state.h"

#include <condition_variable>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "server/observability/log_context.h"
#include "server/snapshots/session_snapshot.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {

grpc::Status ServerState::ToGrpc(Rpc rpc, const absl::Status& status) {
  if (status.ok()) return grpc::Status::OK;
  metrics.RecordError(rpc, status.code());
  // absl and gRPC share the canonical code numbering.
  return grpc::Status(static_cast<grpc::StatusCode>(status.code()), std::string(status.message()));
}

void ServerState::RecordSolve(const v1::SolveResult& result, const SessionEntry* session, double queue_wait_s,
                              double latency_s) {
  metrics.RecordSolve(result, queue_wait_s, latency_s);
  if (options.slow_solve_ms <= 0.0 || !(result.solve_ms() > options.slow_solve_ms)) return;
  const LogContext context(session != nullptr ? absl::string_view(session->id) : absl::string_view("SolveOnce"),
                           session != nullptr ? absl::string_view(session->owner.principal) : absl::string_view());
  const v1::Dimensions* dims = session != nullptr ? &session->dims : nullptr;
  spdlog::warn(
      "slow solve: {:.3f} ms in the solver (--slow_solve_ms {}), {} iterations, status {}, queue wait {:.3f} ms{}",
      result.solve_ms(), options.slow_solve_ms, result.iterations(), v1::SolveStatus_Name(result.status()),
      queue_wait_s * 1e3,
      dims == nullptr ? std::string()
                      : absl::StrCat(", M=", dims->num_states(), " L=", dims->num_inputs(), " K=", dims->num_outputs(),
                                     " N=", dims->horizon()));
}

void ServerState::FillLimits(v1::ServerLimits* out) const {
  out->set_max_sessions(options.max_sessions);
  out->set_max_horizon(options.size_limits.max_horizon);
  out->set_max_states(options.size_limits.max_states);
  out->set_max_inputs(options.size_limits.max_inputs);
  out->set_max_outputs(options.size_limits.max_outputs);
  out->set_max_iterations(options.size_limits.max_iterations);
  out->set_max_message_bytes(options.max_message_bytes);
  out->set_session_idle_timeout_s(options.session_idle_timeout_s);
  out->set_session_compact_idle_s(options.session_compact_idle_s);
  out->set_worker_threads(options.worker_threads);
  out->set_queue_capacity(options.queue_capacity);
  out->set_max_queue_wait_ms(options.max_queue_wait_ms);
  out->set_max_gp_points(options.size_limits.max_gp_points);
  out->set_max_input_levels(options.size_limits.max_input_levels);
  out->set_max_keep_out_regions(options.size_limits.max_keep_out_regions);
  out->set_max_session_bytes(options.size_limits.max_session_bytes);
  out->set_max_pass_flops(options.size_limits.max_pass_flops);
  out->set_max_spec_scalars(options.size_limits.max_scalars);
  out->set_memory_budget_bytes(budget.capacity());
  out->set_max_control_streams(options.max_control_streams);
  out->set_max_stream_answers(options.max_stream_answers);
  out->set_max_streams_per_connection(options.max_streams_per_connection);
  out->set_first_message_timeout_s(options.first_message_timeout_s);
  out->set_connection_idle_timeout_s(options.connection_idle_timeout_s);
  out->set_inline_solve_max_ms(options.inline_solve_max_ms);
  out->set_max_fleet_steps(static_cast<std::uint32_t>(options.max_fleet_steps));
  out->set_solver_cores(static_cast<std::uint32_t>(pool.cores()));
}

std::optional<Clock::time_point> SteadyDeadline(const grpc::CallbackServerContext& context) {
  const auto deadline = context.deadline();
  if (deadline == std::chrono::system_clock::time_point::max()) return std::nullopt;
  return Clock::now() + std::chrono::duration_cast<Clock::duration>(deadline - std::chrono::system_clock::now());
}

bool ServerState::MayRestore(const std::string& id, const Caller& caller) const {
  return snapshots != nullptr && absl::IsNotFound(registry.Find(id, caller).status());
}

absl::StatusOr<std::shared_ptr<SessionEntry>> ServerState::FindOrRestore(const std::string& id, const Caller& caller,
                                                                         bool by_control_stream) {
  absl::StatusOr<std::shared_ptr<SessionEntry>> found = registry.Find(id, caller);
  if (snapshots == nullptr || !absl::IsNotFound(found.status())) return found;
  absl::StatusOr<snapshot::v1::SessionSnapshot> snapshot = snapshots->Claim(id, caller, by_control_stream);
  if (!snapshot.ok()) return found;
  absl::StatusOr<std::shared_ptr<SessionEntry>> restored =
      RestoreSnapshot(*snapshot, options.size_limits, &gp_models, &budget, &registry);
  const LogContext log_context(snapshot->session_id(), snapshot->owner_principal());
  if (!restored.ok()) {
    // Its client re-creates the session (cold), as without a snapshot.
    spdlog::error("session {}: its snapshot could not be restored: {}", snapshot->session_id(),
                  std::string(restored.status().message()));
    snapshots_failed.fetch_add(1, std::memory_order_relaxed);
    return found;
  }
  snapshots_restored.fetch_add(1, std::memory_order_relaxed);
  spdlog::info("session {} restored from its snapshot ({} solves before)", snapshot->session_id(), snapshot->solves());
  return restored;
}

int ServerState::WriteSnapshots(Clock::time_point until) {
  if (snapshots == nullptr) return 0;
  // Each on its session's strand, right after a task still in flight there (a solve that
  // has sent its answer may still be finishing): what its next step would start from.
  struct Pending {
    std::mutex mu;
    std::condition_variable done;
    std::size_t left = 0;
    int written = 0;
  };
  const auto pending = std::make_shared<Pending>();
  const std::vector<std::shared_ptr<SessionEntry>> sessions = registry.List();
  pending->left = sessions.size();
  for (const std::shared_ptr<SessionEntry>& entry : sessions) {
    SessionStrand::RunExclusive(entry->strand, pool, [this, entry, pending] {
      bool ok = false;
      if (!entry->closed) {
        absl::StatusOr<snapshot::v1::SessionSnapshot> snapshot = TakeSnapshot(*entry);
        const absl::Status status = snapshot.ok() ? snapshots->Write(*snapshot) : snapshot.status();
        ok = status.ok();
        if (!ok) {
          const LogContext log_context(entry->id, entry->owner.principal);
          spdlog::error("session {}: no snapshot written: {}", entry->id, std::string(status.message()));
        }
      }
      if (ok) snapshots_written.fetch_add(1, std::memory_order_relaxed);
      const std::lock_guard<std::mutex> lock(pending->mu);
      --pending->left;
      pending->written += ok ? 1 : 0;
      pending->done.notify_all();
    });
  }
  std::unique_lock<std::mutex> lock(pending->mu);
  pending->done.wait_until(lock, until, [&] { return pending->left == 0; });
  if (pending->left > 0) {
    spdlog::warn("{} sessions still solving: their snapshots are written only if they finish before the process ends",
                 pending->left);
  }
  return pending->written;
}

}  // namespace nupmpc::server
