#include "server/sessions/model_storage.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "core/public/footprint.h"

namespace nupmpc::server {

absl::Status ReserveModelStorage(const core::MpcSession& session, const core::ModelChanges& changes,
                                 SessionMemory* memory) {
  const core::Problem& problem = session.problem();
  if (!core::ModelChangesStorage(problem, changes)) return absl::OkStatus();
  core::ProblemShape shape = core::ShapeOf(problem, session.algorithm());
  shape.a_per_step = shape.a_per_step || !changes.A.empty();
  shape.b_per_step = shape.b_per_step || !changes.B.empty();
  shape.c_per_step = shape.c_per_step || !changes.C.empty();
  const core::Footprint f = core::EstimateFootprint(shape);
  const std::int64_t resident = f.problem_bytes + f.carried_bytes;
  const std::int64_t peak = resident + f.workspace_bytes + f.transient_bytes;
  if (memory->max_session_bytes > 0 && peak > memory->max_session_bytes) {
    return absl::ResourceExhaustedError(
        absl::StrCat("step.model: a per-step model makes the session need an estimated ", (peak + (1 << 20) - 1) >> 20,
                     " MiB, over the server's per-session limit (ServerLimits.max_session_bytes) of ",
                     (memory->max_session_bytes + (1 << 20) - 1) >> 20, " MiB"));
  }
  return memory->resident.GrowTo(std::max(resident, memory->resident.bytes()),
                                 "step.model (the session's model, now per-step)");
}

}  // namespace nupmpc::server
