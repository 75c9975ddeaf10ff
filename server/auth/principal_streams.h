#ifndef NUPMPC_SERVER_AUTH_PRINCIPAL_STREAMS_H_
#define NUPMPC_SERVER_AUTH_PRINCIPAL_STREAMS_H_

#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "absl/status/status.h"

namespace nupmpc::server {

// Control streams open per authenticated principal, bounded by --max_streams_per_principal
// (0: no own limit; calls without a principal are not counted), and how to end each one
// when its principal loses its access (a token removed from --auth_tokens_file: new calls
// are refused by authentication, open streams only through this). Thread-safe.
class PrincipalStreams {
 public:
  explicit PrincipalStreams(int max_per_principal) : max_per_principal_(max_per_principal) {}

  // Counts stream `key` of `principal`; RESOURCE_EXHAUSTED naming the quota when it holds
  // all it may. `revoke` ends the stream (called by Revoked's caller, never under this
  // class's lock; it may be called more than once; null: a principal that cannot lose its
  // access here, e.g. a client certificate's). Every OK must be matched by one Release.
  absl::Status Acquire(const std::string& principal, const void* key, std::function<void()> revoke);
  void Release(const std::string& principal, const void* key);

  // The revoke callbacks of the open streams whose principal `has_access` no longer accepts.
  std::vector<std::function<void()>> Revoked(const std::function<bool(const std::string&)>& has_access);

 private:
  const int max_per_principal_;
  std::mutex mu_;
  std::unordered_map<std::string, std::map<const void*, std::function<void()>>> open_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_AUTH_PRINCIPAL_STREAMS_H_
