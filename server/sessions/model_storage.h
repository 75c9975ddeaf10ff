#ifndef NUPMPC_SERVER_SESSIONS_MODEL_STORAGE_H_
#define NUPMPC_SERVER_SESSIONS_MODEL_STORAGE_H_

// A Step's model update may make a session's time-invariant A, B or C per-step (a
// linearised nonlinear plant, a time-varying model): the session then keeps N matrices
// where it kept one. That memory is admitted like a new session's, before the update is
// applied: within the per-session limit, and reserved in the server's budget.

#include "absl/status/status.h"
#include "core/nupmpc.h"
#include "core/public/model_update.h"
#include "server/sessions/session_registry.h"

namespace nupmpc::server {

// OK when `changes` keep the session's storage or the per-step model fits; then
// `memory`'s resident reservation holds the larger session. RESOURCE_EXHAUSTED naming
// step.model otherwise (nothing changed).
absl::Status ReserveModelStorage(const core::MpcSession& session, const core::ModelChanges& changes,
                                 SessionMemory* memory);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SESSIONS_MODEL_STORAGE_H_
