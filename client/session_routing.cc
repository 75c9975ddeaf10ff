#include "client/session_routing.h"

#include <algorithm>
#include <random>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace nupmpc {

std::string NewSessionId() {
  // std::random_device reads the kernel's CSPRNG (getrandom) on Linux.
  static thread_local std::random_device device;
  std::string id;
  for (int i = 0; i < 4; ++i) absl::StrAppend(&id, absl::StrFormat("%08x", device()));
  return id;
}

void RouteToSession(grpc::ClientContext* context, const std::string& session_id) {
  // Only an id of the server's form: anything else is refused by the server whichever
  // replica gets it, and a long one would overflow gRPC's metadata limit before the
  // server could say why.
  const bool well_formed = session_id.size() == 32 && std::all_of(session_id.begin(), session_id.end(),
                                                                  [](char c) { return absl::ascii_isxdigit(c); });
  if (well_formed) context->AddMetadata(kSessionHeader, session_id);
}

}  // namespace nupmpc
