#include "core/nupmpc.h"

#include <utility>

#include "core/session/session.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {

absl::StatusOr<std::unique_ptr<MpcSession>> CreateSession(Problem problem, SolverOptions options) {
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<Session> session, Session::Create(std::move(problem), options));
  return std::unique_ptr<MpcSession>(std::move(session));
}

absl::StatusOr<std::unique_ptr<MpcSession>> CreateSession(Problem problem, InputMap map, SolverOptions options) {
  const Dimensions caller = DimensionsOf(problem);
  NUPMPC_ASSIGN_OR_RETURN(Problem mapped, MapInputs(std::move(problem), map));
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<MpcSession> inner, CreateSession(std::move(mapped), options));
  return InputMappedSession::Wrap(std::move(inner), std::move(map), caller);
}

}  // namespace nupmpc::core
