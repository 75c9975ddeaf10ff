#ifndef NUPMPC_CORE_PUBLIC_STATUS_MACROS_H_
#define NUPMPC_CORE_PUBLIC_STATUS_MACROS_H_

// NUPMPC_RETURN_IF_ERROR and NUPMPC_ASSIGN_OR_RETURN, for code built on the core's
// absl::Status results.
// Code outside core/ includes the core through core/nupmpc.h and core/public/ only
// (tests/build/layering_check.py); this header forwards to where the core keeps it.

#include "core/util/status_macros.h"  // IWYU pragma: export

#endif  // NUPMPC_CORE_PUBLIC_STATUS_MACROS_H_
