#include "server/snapshots/session_snapshot.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "core/public/status_macros.h"
#include "server/snapshots/sealed_snapshot.h"

namespace nupmpc::server {

absl::StatusOr<snapshot::v1::SessionSnapshot> TakeSnapshot(SessionEntry& entry) {
  if (entry.spec == nullptr) {
    return absl::FailedPreconditionError(
        absl::StrCat("session ", QuoteSessionId(entry.id), ": kept without its spec (the server has no --state_dir)"));
  }
  snapshot::v1::SessionSnapshot out;
  out.set_format_version(kSnapshotFormatVersion);
  out.set_session_id(entry.id);
  out.set_owner_principal(entry.owner.principal);
  out.set_owner_connection(entry.owner.connection);
  out.set_owned_by_stream(entry.owned_by_stream);
  *out.mutable_spec() = *entry.spec;
  NUPMPC_RETURN_IF_ERROR(entry.solver->SaveState(out.mutable_core_state()));
  out.set_written_unix_ms(UnixMillisecondsNow());
  out.set_solves(entry.solves.load());
  out.set_last_solve_ms(entry.last_solve_ms.load());
  out.set_last_solve_cpu_ms(entry.last_solve_cpu_ms.load());
  out.set_last_pass_ms(entry.last_pass_ms.load());
  out.set_shortest_pass_ms(entry.shortest_pass_ms.load());
  return out;
}

absl::StatusOr<std::shared_ptr<SessionEntry>> RestoreSnapshot(const snapshot::v1::SessionSnapshot& snapshot,
                                                              const SizeLimits& limits, GpModelCache* gp_models,
                                                              MemoryBudget* budget, SessionRegistry* registry) {
  NUPMPC_RETURN_IF_ERROR(CheckRequestedSessionId(snapshot.session_id()));
  const SessionOwner owner{snapshot.owner_principal(), snapshot.owner_connection()};
  NUPMPC_RETURN_IF_ERROR(registry->CheckQuota(owner));
  NUPMPC_ASSIGN_OR_RETURN(BuiltSession built, BuildSession(snapshot.spec(), limits, gp_models, nullptr, budget));
  if (const absl::Status restored = built.solver->RestoreState(snapshot.core_state()); !restored.ok()) {
    return absl::Status(restored.code(), absl::StrCat("snapshot core_state: ", restored.message()));
  }
  NUPMPC_ASSIGN_OR_RETURN(std::shared_ptr<SessionEntry> entry,
                          registry->Add(std::move(built.solver), built.timing, snapshot.owned_by_stream(),
                                        std::move(built.memory), snapshot.session_id(), owner,
                                        std::make_shared<const v1::ProblemSpec>(snapshot.spec()), /*restored=*/true));
  entry->solves.store(snapshot.solves());
  entry->last_solve_ms.store(snapshot.last_solve_ms());
  entry->last_solve_cpu_ms.store(snapshot.last_solve_cpu_ms());
  entry->last_pass_ms.store(snapshot.last_pass_ms());
  entry->shortest_pass_ms.store(snapshot.shortest_pass_ms());
  return entry;
}

}  // namespace nupmpc::server
