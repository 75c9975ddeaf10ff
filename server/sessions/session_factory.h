#ifndef NUPMPC_SERVER_SESSIONS_SESSION_FACTORY_H_
#define NUPMPC_SERVER_SESSIONS_SESSION_FACTORY_H_

// A spec becomes a core session: admission by cost, conversion, and the session kind the
// spec asks for (linear, keep-out, GP; multi-level inputs or input differences around the
// first two). Shared by CreateSession, SolveOnce and Control streams that carry a spec.

#include <memory>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/nupmpc.h"
#include "nupmpc/v1/nupmpc.pb.h"
#include "server/convert/gp_model_cache.h"
#include "server/convert/spec_conversion.h"
#include "server/sessions/call_context.h"
#include "server/sessions/memory_budget.h"
#include "server/sessions/session_registry.h"

namespace nupmpc::server {

struct BuiltSession {
  std::unique_ptr<core::MpcSession> solver;
  SessionTiming timing;
  SessionMemory memory;  ///< its share of the budget (empty without one)
};

// Admission first: the spec's cost (server/convert/session_cost.h) is checked against the
// per-session limits and, with a budget, reserved in it before anything is converted or
// allocated. GP specs take their factorised model from `gp_models` when given (shared
// between sessions); a kernel fit or factorisation on creation stops at `call`'s deadline
// or cancellation.
absl::StatusOr<BuiltSession> BuildSession(const v1::ProblemSpec& spec, const SizeLimits& limits,
                                          GpModelCache* gp_models = nullptr, const CallContext* call = nullptr,
                                          MemoryBudget* budget = nullptr);

// CreateSession and a Control stream's spec: BuildSession, then registers the session
// (under `requested_id` when not empty, see SessionRegistry::Add; owned by `owner`) unless
// the call's deadline passed or its client cancelled meanwhile (nobody could reach a
// session registered then). The owner's session quota is checked before the build too.
// `keep_spec`: the session keeps a copy of its spec (SessionEntry::spec, for snapshots).
absl::StatusOr<std::shared_ptr<SessionEntry>> CreateAndRegister(const v1::ProblemSpec& spec, const SizeLimits& limits,
                                                                GpModelCache* gp_models, MemoryBudget* budget,
                                                                SessionRegistry* registry, const CallContext& call,
                                                                bool owned_by_stream, absl::string_view requested_id,
                                                                const SessionOwner& owner, bool keep_spec = false);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_SESSIONS_SESSION_FACTORY_H_
