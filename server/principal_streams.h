#ifndef NUPMPC_SERVER_PRINCIPAL_STREAMS_H_
#define NUPMPC_SERVER_PRINCIPAL_STREAMS_H_

#include <mutex>
#include <string>
#include <unordered_map>

#include "absl/status/status.h"

namespace nupmpc::server {

// Control streams open per authenticated principal, bounded by --max_streams_per_principal
// (0: no own limit; calls without a principal are not counted). Thread-safe.
class PrincipalStreams {
 public:
  explicit PrincipalStreams(int max_per_principal) : max_per_principal_(max_per_principal) {}

  // Counts a stream of `principal`; RESOURCE_EXHAUSTED naming the quota when it holds all
  // it may. Every OK must be matched by one Release.
  absl::Status Acquire(const std::string& principal);
  void Release(const std::string& principal);

 private:
  const int max_per_principal_;
  std::mutex mu_;
  std::unordered_map<std::string, int> open_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_PRINCIPAL_STREAMS_H_
