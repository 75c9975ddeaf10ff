#ifndef NUPMPC_CLIENT_STATUS_MACROS_H_
#define NUPMPC_CLIENT_STATUS_MACROS_H_

// The client's own status macros: core/util/status_macros.h is the core's, which client/ may not include.

#include "absl/status/status.h"

#define NUPMPC_CLIENT_RETURN_IF_ERROR(expr)                                           \
  do {                                                                                \
    if (::absl::Status nupmpc_client_status_ = (expr); !nupmpc_client_status_.ok()) { \
      return nupmpc_client_status_;                                                   \
    }                                                                                 \
  } while (false)

#endif  // NUPMPC_CLIENT_STATUS_MACROS_H_
