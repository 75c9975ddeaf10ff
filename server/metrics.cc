#include "server/metrics.h"

#include <algorithm>
#include <limits>

namespace nupmpc::server {

void Metrics::RecordSolve(double latency_ms) {
  solves_.fetch_add(1, std::memory_order_relaxed);
  const auto it = std::lower_bound(kBucketUpperMs.begin(), kBucketUpperMs.end(), latency_ms);
  buckets_[it - kBucketUpperMs.begin()].fetch_add(1, std::memory_order_relaxed);
}

void Metrics::RecordError(absl::StatusCode code) {
  const auto index = static_cast<std::size_t>(code);
  if (index < errors_.size()) errors_[index].fetch_add(1, std::memory_order_relaxed);
}

std::uint64_t Metrics::errors(absl::StatusCode code) const {
  const auto index = static_cast<std::size_t>(code);
  return index < errors_.size() ? errors_[index].load(std::memory_order_relaxed) : 0;
}

void Metrics::Fill(v1::GetServerInfoResponse* out) const {
  out->set_solves(solves());
  for (std::size_t code = 1; code < errors_.size(); ++code) {
    const std::uint64_t n = errors_[code].load(std::memory_order_relaxed);
    if (n > 0) (*out->mutable_errors_by_code())[absl::StatusCodeToString(static_cast<absl::StatusCode>(code))] = n;
  }
  for (std::size_t i = 0; i < buckets_.size(); ++i) {
    v1::LatencyBucket* b = out->add_solve_latency();
    b->set_upper_ms(i < kBucketUpperMs.size() ? kBucketUpperMs[i] : std::numeric_limits<double>::infinity());
    b->set_count(buckets_[i].load(std::memory_order_relaxed));
  }
}

}  // namespace nupmpc::server
