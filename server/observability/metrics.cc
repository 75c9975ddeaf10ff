#include "server/observability/metrics.h"

#include <algorithm>
#include <limits>

namespace nupmpc::server {

Histogram::Histogram(std::vector<double> upper_bounds)
    : bounds_(std::move(upper_bounds)), counts_(new std::atomic<std::uint64_t>[bounds_.size() + 1]) {
  for (std::size_t i = 0; i <= bounds_.size(); ++i) counts_[i].store(0, std::memory_order_relaxed);
}

void Histogram::Observe(double value) {
  const auto it = std::lower_bound(bounds_.begin(), bounds_.end(), value);
  counts_[static_cast<std::size_t>(it - bounds_.begin())].fetch_add(1, std::memory_order_relaxed);
  sum_.fetch_add(value, std::memory_order_relaxed);
}

std::vector<std::uint64_t> Histogram::counts() const {
  std::vector<std::uint64_t> out(bounds_.size() + 1);
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = counts_[i].load(std::memory_order_relaxed);
  return out;
}

absl::string_view RpcName(Rpc rpc) {
  switch (rpc) {
    case Rpc::kCreateSession:
      return "CreateSession";
    case Rpc::kControl:
      return "Control";
    case Rpc::kSolve:
      return "Solve";
    case Rpc::kSolveOnce:
      return "SolveOnce";
    case Rpc::kGetSession:
      return "GetSession";
    case Rpc::kListSessions:
      return "ListSessions";
    case Rpc::kCloseSession:
      return "CloseSession";
    case Rpc::kGetServerInfo:
      return "GetServerInfo";
    case Rpc::kFitGpModel:
      return "FitGpModel";
    case Rpc::kSolveFleet:
      return "SolveFleet";
  }
  return "unknown";
}

namespace {

std::size_t SolveIndex(v1::SolveStatus status, v1::Algorithm algorithm) {
  const auto s = std::clamp<int>(status, 0, Metrics::kStatusCount - 1);
  const auto a = std::clamp<int>(algorithm, 0, Metrics::kAlgorithmCount - 1);
  return static_cast<std::size_t>(s) * Metrics::kAlgorithmCount + static_cast<std::size_t>(a);
}

std::size_t ErrorIndex(Rpc rpc, absl::StatusCode code) {
  const auto c = std::clamp<int>(static_cast<int>(code), 0, Metrics::kCodeCount - 1);
  return static_cast<std::size_t>(rpc) * Metrics::kCodeCount + static_cast<std::size_t>(c);
}

}  // namespace

Metrics::Metrics()
    : queue_wait_({kLatencyBucketsS.begin(), kLatencyBucketsS.end()}),
      solve_({kLatencyBucketsS.begin(), kLatencyBucketsS.end()}),
      latency_({kLatencyBucketsS.begin(), kLatencyBucketsS.end()}),
      iterations_({kIterationBuckets.begin(), kIterationBuckets.end()}),
      slack_({kSlackBucketsS.begin(), kSlackBucketsS.end()}) {}

void Metrics::RecordSolve(const v1::SolveResult& result, double queue_wait_s, double latency_s) {
  solves_[SolveIndex(result.status(), result.algorithm())].fetch_add(1, std::memory_order_relaxed);
  queue_wait_.Observe(queue_wait_s);
  solve_.Observe(result.solve_ms() / 1000.0);
  latency_.Observe(latency_s);
  iterations_.Observe(static_cast<double>(result.iterations()));
  if (result.deadline() != v1::DEADLINE_OUTCOME_UNSPECIFIED) {
    deadlines_[static_cast<std::size_t>(std::clamp<int>(result.deadline(), 0, kDeadlineOutcomeCount - 1))].fetch_add(
        1, std::memory_order_relaxed);
    slack_.Observe(result.deadline_slack_ms() / 1000.0);
  }
}

std::uint64_t Metrics::deadlines(v1::DeadlineOutcome outcome) const {
  return deadlines_[static_cast<std::size_t>(std::clamp<int>(outcome, 0, kDeadlineOutcomeCount - 1))].load(
      std::memory_order_relaxed);
}

void Metrics::RecordError(Rpc rpc, absl::StatusCode code) {
  if (code == absl::StatusCode::kOk) return;
  errors_[ErrorIndex(rpc, code)].fetch_add(1, std::memory_order_relaxed);
}

std::uint64_t Metrics::solves() const {
  std::uint64_t n = 0;
  for (const auto& c : solves_) n += c.load(std::memory_order_relaxed);
  return n;
}

std::uint64_t Metrics::solves(v1::SolveStatus status, v1::Algorithm algorithm) const {
  return solves_[SolveIndex(status, algorithm)].load(std::memory_order_relaxed);
}

std::uint64_t Metrics::errors(Rpc rpc, absl::StatusCode code) const {
  return errors_[ErrorIndex(rpc, code)].load(std::memory_order_relaxed);
}

std::uint64_t Metrics::errors(absl::StatusCode code) const {
  std::uint64_t n = 0;
  for (int r = 0; r < kRpcCount; ++r) n += errors(static_cast<Rpc>(r), code);
  return n;
}

void Metrics::Fill(v1::GetServerInfoResponse* out) const {
  out->set_solves(solves());
  for (int code = 1; code < kCodeCount; ++code) {
    const std::uint64_t n = errors(static_cast<absl::StatusCode>(code));
    if (n > 0) (*out->mutable_errors_by_code())[absl::StatusCodeToString(static_cast<absl::StatusCode>(code))] = n;
  }
  const std::vector<std::uint64_t> counts = latency_.counts();
  for (std::size_t i = 0; i < counts.size(); ++i) {
    v1::LatencyBucket* b = out->add_solve_latency();
    b->set_upper_ms(i < kLatencyBucketsS.size() ? kLatencyBucketsS[i] * 1000.0
                                                : std::numeric_limits<double>::infinity());
    b->set_count(counts[i]);
  }
}

}  // namespace nupmpc::server
