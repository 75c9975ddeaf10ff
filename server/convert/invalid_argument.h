#ifndef NUPMPC_SERVER_CONVERT_INVALID_ARGUMENT_H_
#define NUPMPC_SERVER_CONVERT_INVALID_ARGUMENT_H_

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace nupmpc::server {

// INVALID_ARGUMENT with a message made of `parts` (the field's path first, then the rule it
// breaks): how every conversion of a request names what it refuses.
template <typename... Parts>
absl::Status InvalidArgument(const Parts&... parts) {
  return absl::InvalidArgumentError(absl::StrCat(parts...));
}

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_CONVERT_INVALID_ARGUMENT_H_
