#include "core/nupmpc.h"

#include <utility>

#include "core/session/session.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {

absl::StatusOr<std::unique_ptr<MpcSession>> CreateSession(Problem problem, SolverOptions options) {
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<Session> session, Session::Create(std::move(problem), options));
  return std::unique_ptr<MpcSession>(std::move(session));
}

}  // namespace nupmpc::core
