#ifndef NUPMPC_SERVER_METRICS_H_
#define NUPMPC_SERVER_METRICS_H_

#include <array>
#include <atomic>

#include "absl/status/status.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {

// Lock-free counters for GetServerInfo: solves, RPC errors by canonical code, and a
// latency histogram (queue wait + solve) with fixed millisecond buckets.
class Metrics {
 public:
  static constexpr std::array<double, 14> kBucketUpperMs = {0.05, 0.1, 0.2, 0.5, 1,   2,   5,
                                                           10,   20,  50,  100, 200, 500, 1000};

  void RecordSolve(double latency_ms);
  void RecordError(absl::StatusCode code);
  void Fill(v1::GetServerInfoResponse* out) const;
  std::uint64_t solves() const { return solves_.load(std::memory_order_relaxed); }
  std::uint64_t errors(absl::StatusCode code) const;

 private:
  std::atomic<std::uint64_t> solves_{0};
  std::array<std::atomic<std::uint64_t>, 17> errors_{};
  std::array<std::atomic<std::uint64_t>, kBucketUpperMs.size() + 1> buckets_{};
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_METRICS_H_
