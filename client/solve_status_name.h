#ifndef NUPMPC_CLIENT_SOLVE_STATUS_NAME_H_
#define NUPMPC_CLIENT_SOLVE_STATUS_NAME_H_

#include <string>

#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc {

// SOLVE_STATUS_TIME_LIMIT → "time_limit": the names the core and nupmpc-bench print.
std::string SolveStatusName(v1::SolveStatus status);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_SOLVE_STATUS_NAME_H_
