#ifndef NUPMPC_SERVER_OBSERVABILITY_METRICS_H_
#define NUPMPC_SERVER_OBSERVABILITY_METRICS_H_

// The server's counters and histograms: one source for GetServerInfo and the Prometheus
// endpoint (server/metrics_exposition.h). Lock-free; recording is a few relaxed atomic
// adds, so it is always on.

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::server {

// Observations in fixed buckets: counts[i] are those in (bounds[i-1], bounds[i]], the last
// one those above every bound.
class Histogram {
 public:
  explicit Histogram(std::vector<double> upper_bounds);
  void Observe(double value);
  const std::vector<double>& upper_bounds() const { return bounds_; }
  std::vector<std::uint64_t> counts() const;
  double sum() const { return sum_.load(std::memory_order_relaxed); }

 private:
  std::vector<double> bounds_;
  std::unique_ptr<std::atomic<std::uint64_t>[]> counts_;
  std::atomic<double> sum_{0.0};
};

// The RPCs of nupmpc.v1.MpcService, as the label of the error counter.
enum class Rpc {
  kCreateSession,
  kControl,
  kSolve,
  kSolveOnce,
  kGetSession,
  kListSessions,
  kCloseSession,
  kGetServerInfo,
  kFitGpModel,
  kSolveFleet,
};
inline constexpr int kRpcCount = 10;
absl::string_view RpcName(Rpc rpc);

class Metrics {
 public:
  // Seconds; also GetServerInfo's solve_latency buckets (in milliseconds there).
  static constexpr std::array<double, 14> kLatencyBucketsS = {0.00005, 0.0001, 0.0002, 0.0005, 0.001, 0.002, 0.005,
                                                              0.01,    0.02,   0.05,   0.1,    0.2,   0.5,   1};
  static constexpr std::array<double, 12> kIterationBuckets = {1, 2, 3, 5, 10, 20, 50, 100, 200, 500, 1000, 10000};
  // Seconds a step's answer was handed over before (positive) or after (negative) its deadline.
  static constexpr std::array<double, 15> kSlackBucketsS = {-1,    -0.1, -0.01, -0.001, 0,   0.0005, 0.001, 0.002,
                                                            0.005, 0.01, 0.02,  0.05,   0.1, 0.5,    1};
  static constexpr int kDeadlineOutcomeCount = 4;  // v1::DeadlineOutcome values
  static constexpr int kStatusCount = 8;           // v1::SolveStatus values a server sends (not HELD)
  static constexpr int kAlgorithmCount = 4;        // v1::Algorithm values
  static constexpr int kCodeCount = 17;            // canonical status codes

  Metrics();

  // A solve that produced `result` (of any status), queued for `queue_wait_s` before it
  // ran, answered `latency_s` after it was queued.
  void RecordSolve(const v1::SolveResult& result, double queue_wait_s, double latency_s);
  void RecordError(Rpc rpc, absl::StatusCode code);

  std::uint64_t solves() const;
  std::uint64_t solves(v1::SolveStatus status, v1::Algorithm algorithm) const;
  std::uint64_t errors(Rpc rpc, absl::StatusCode code) const;
  std::uint64_t errors(absl::StatusCode code) const;  // over every RPC
  // Steps with a deadline answered with `outcome` (never DEADLINE_OUTCOME_UNSPECIFIED).
  std::uint64_t deadlines(v1::DeadlineOutcome outcome) const;
  const Histogram& deadline_slack_seconds() const { return slack_; }
  const Histogram& queue_wait_seconds() const { return queue_wait_; }
  const Histogram& solve_seconds() const { return solve_; }
  const Histogram& latency_seconds() const { return latency_; }
  const Histogram& iterations() const { return iterations_; }

  // GetServerInfo's counters: solves, errors by code, the latency histogram.
  void Fill(v1::GetServerInfoResponse* out) const;

 private:
  std::array<std::atomic<std::uint64_t>, kStatusCount * kAlgorithmCount> solves_{};
  std::array<std::atomic<std::uint64_t>, kRpcCount * kCodeCount> errors_{};
  Histogram queue_wait_;
  Histogram solve_;
  Histogram latency_;
  Histogram iterations_;
  std::array<std::atomic<std::uint64_t>, kDeadlineOutcomeCount> deadlines_{};
  Histogram slack_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_OBSERVABILITY_METRICS_H_
