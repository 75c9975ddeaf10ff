#ifndef NUPMPC_SERVER_SNAPSHOTS_SESSION_SNAPSHOT_H_
#define NUPMPC_SERVER_SNAPSHOTS_SESSION_SNAPSHOT_H_

// A registered session as a snapshot, and a snapshot back into a session: its creation
// spec, the core's state (current values and warm start, core::MpcSession::SaveState), its
// owner and counters.

#include <memory>

#include "absl/status/statusor.h"
#include "nupmpc/snapshot/v1/session_snapshot.pb.h"
#include "server/convert/gp_model_cache.h"
#include "server/sessions/memory_budget.h"
#include "server/sessions/session_factory.h"
#include "server/sessions/session_registry.h"

namespace nupmpc::server {

// Only on the session's strand (no solve in flight). FAILED_PRECONDITION for a session
// kept without its spec; UNIMPLEMENTED for a kind the core cannot snapshot.
absl::StatusOr<snapshot::v1::SessionSnapshot> TakeSnapshot(SessionEntry& entry);

// Builds the session from the snapshot's spec (admission and budget as CreateSession),
// puts its state back and registers it under its id and owner, with its counters.
// INVALID_ARGUMENT when the state does not fit the spec; the session is then discarded.
absl::StatusOr<std::shared_ptr<SessionEntry>> RestoreSnapshot(const snapshot::v1::SessionSnapshot& snapshot,
                                                              const SizeLimits& limits, GpModelCache* gp_models,
                                                              MemoryBudget* budget, SessionRegistry* registry);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SNAPSHOTS_SESSION_SNAPSHOT_H_
