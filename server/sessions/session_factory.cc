#include "server/sessions/session_factory.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/nupmpc.h"
#include "core/public/nonlinear.h"
#include "core/public/session.h"
#include "core/public/status_macros.h"
#include "server/convert/gp_conversion.h"
#include "server/convert/input_map_conversion.h"
#include "server/convert/keep_out_conversion.h"
#include "server/convert/session_cost.h"

namespace nupmpc::server {
namespace {

// The linear kinds: a plain or keep-out session of the mapped problem, wrapped by the
// input map when the spec has multi-level inputs or input differences.
absl::StatusOr<std::unique_ptr<core::MpcSession>> LinearSession(const v1::ProblemSpec& spec, const SizeLimits& limits) {
  NUPMPC_ASSIGN_OR_RETURN(core::Problem base, ProblemFromSpec(spec, limits));
  NUPMPC_ASSIGN_OR_RETURN(core::InputMap map, InputMapFromSpec(spec, base));
  const core::Dimensions caller = core::DimensionsOf(base);
  absl::StatusOr<core::Problem> mapped = core::MapInputs(std::move(base), map);
  if (!mapped.ok()) return absl::Status(mapped.status().code(), absl::StrCat("spec.", mapped.status().message()));
  NUPMPC_ASSIGN_OR_RETURN(const core::SolverOptions options, OptionsFromSpec(spec.options(), limits));
  absl::StatusOr<std::unique_ptr<core::MpcSession>> inner;
  if (spec.has_keep_out()) {
    NUPMPC_ASSIGN_OR_RETURN(core::KeepOut keep_out,
                            KeepOutFromSpec(spec.keep_out(), static_cast<int>(spec.model().num_outputs())));
    NUPMPC_ASSIGN_OR_RETURN(const core::SequentialOptions sequential, SequentialOptionsFromSpec(spec.keep_out()));
    inner = core::KeepOutSession::Create(*std::move(mapped), std::move(keep_out), options, sequential);
  } else {
    inner = core::Session::Create(*std::move(mapped), options);
  }
  if (!inner.ok()) {
    // e.g. a forced algorithm that cannot handle the priors: the spec's fault.
    return absl::Status(inner.status().code(), absl::StrCat("spec: ", inner.status().message()));
  }
  return core::InputMappedSession::Wrap(*std::move(inner), std::move(map), caller);
}

}  // namespace

absl::StatusOr<BuiltSession> BuildSession(const v1::ProblemSpec& spec, const SizeLimits& limits,
                                          GpModelCache* gp_models, const CallContext* call, MemoryBudget* budget) {
  NUPMPC_ASSIGN_OR_RETURN(const SessionCost cost, SpecCost(spec, limits));
  MemoryBudget::Reservation reserved;
  if (budget != nullptr) {
    NUPMPC_ASSIGN_OR_RETURN(reserved, budget->Reserve(std::max(cost.build_bytes, cost.session_bytes()),
                                                      "spec (the session's problem, solver scratch and GP factors)"));
  }
  BuiltSession built;
  if (spec.has_gp()) {
    NUPMPC_ASSIGN_OR_RETURN(const gp::FitOptions fit, FitLimits(call));
    NUPMPC_ASSIGN_OR_RETURN(built.solver, GpSessionFromSpec(spec, limits, gp_models, fit));
  } else {
    NUPMPC_ASSIGN_OR_RETURN(built.solver, LinearSession(spec, limits));
  }
  NUPMPC_ASSIGN_OR_RETURN(built.timing, SessionTimingFromSpec(spec));
  reserved.ShrinkTo(cost.session_bytes());
  built.memory.scratch = reserved.Split(cost.scratch_bytes);
  built.memory.scratch_bytes = built.memory.scratch.bytes();
  built.memory.resident = std::move(reserved);
  built.memory.max_session_bytes = limits.max_session_bytes;
  return built;
}

absl::StatusOr<std::shared_ptr<SessionEntry>> CreateAndRegister(const v1::ProblemSpec& spec, const SizeLimits& limits,
                                                                GpModelCache* gp_models, MemoryBudget* budget,
                                                                SessionRegistry* registry, const CallContext& call,
                                                                bool owned_by_stream, absl::string_view requested_id,
                                                                const SessionOwner& owner, bool keep_spec) {
  NUPMPC_RETURN_IF_ERROR(registry->CheckQuota(owner));
  NUPMPC_ASSIGN_OR_RETURN(BuiltSession built, BuildSession(spec, limits, gp_models, &call, budget));
  NUPMPC_RETURN_IF_ERROR(CheckCallStillWanted(call, "the session was built"));
  std::shared_ptr<const v1::ProblemSpec> kept = keep_spec ? std::make_shared<const v1::ProblemSpec>(spec) : nullptr;
  return registry->Add(std::move(built.solver), built.timing, owned_by_stream, std::move(built.memory), requested_id,
                       owner, std::move(kept));
}

}  // namespace nupmpc::server
