#ifndef NUPMPC_CORE_UTIL_STATUS_MACROS_H_
#define NUPMPC_CORE_UTIL_STATUS_MACROS_H_

// Abseil 20220623 (Debian 12) has no status macros; these are ours, used everywhere.

#include "absl/status/status.h"
#include "absl/status/statusor.h"

#define NUPMPC_RETURN_IF_ERROR(expr)                 \
  do {                                               \
    const ::absl::Status nupmpc_status_ = (expr);    \
    if (!nupmpc_status_.ok()) return nupmpc_status_; \
  } while (false)

#define NUPMPC_STATUS_CONCAT_INNER_(a, b) a##b
#define NUPMPC_STATUS_CONCAT_(a, b) NUPMPC_STATUS_CONCAT_INNER_(a, b)

#define NUPMPC_ASSIGN_OR_RETURN(lhs, expr) \
  NUPMPC_ASSIGN_OR_RETURN_IMPL_(NUPMPC_STATUS_CONCAT_(nupmpc_statusor_, __LINE__), lhs, expr)

#define NUPMPC_ASSIGN_OR_RETURN_IMPL_(statusor, lhs, expr) \
  auto statusor = (expr);                                  \
  if (!statusor.ok()) return statusor.status();            \
  lhs = std::move(statusor).value()

#endif  // NUPMPC_CORE_UTIL_STATUS_MACROS_H_
