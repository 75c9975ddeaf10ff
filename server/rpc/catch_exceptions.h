#ifndef NUPMPC_SERVER_RPC_CATCH_EXCEPTIONS_H_
#define NUPMPC_SERVER_RPC_CATCH_EXCEPTIONS_H_

#include <functional>

#include "absl/status/status.h"

namespace nupmpc::server {

// Runs a request's work on a worker and turns an exception escaping it into the request's
// status, so that it ends that request only: std::bad_alloc (an allocation the memory
// budget did not foresee) → RESOURCE_EXHAUSTED, anything else → INTERNAL. Logged with
// `what` (e.g. "CreateSession").
absl::Status RunCatchingExceptions(const char* what, const std::function<absl::Status()>& work);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_RPC_CATCH_EXCEPTIONS_H_
