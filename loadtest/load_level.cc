#include "loadtest/load_level.h"

#include <algorithm>
#include <cstdio>
#include <memory>
#include <numeric>
#include <random>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/channel_factory.h"
#include "loadtest/quantile.h"

namespace nupmpc::loadtest {
namespace {

// Every simulated controller gets its own TCP connection, as separate plant computers
// would (gRPC would otherwise share one connection between channels to the same target).
absl::StatusOr<std::shared_ptr<grpc::Channel>> OwnConnection(const std::string& target,
                                                             const ChannelSecurity& security) {
  ChannelOptions options;
  options.own_connection = true;
  options.unlimited_receive = true;
  return OpenChannel(target, security, options);
}

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

std::uint64_t Answered(const std::vector<std::unique_ptr<LoadStream>>& streams) {
  std::uint64_t n = 0;
  for (const auto& s : streams) n += s->answered();
  return n;
}

void PrintProgress(const LevelConfig& config, double elapsed_s, double total_s, std::uint64_t answered,
                   std::uint64_t answered_before) {
  std::fprintf(stderr, "  C=%d %s: %5.1f/%.1f s, %llu solves answered, %.0f/s\n", config.concurrency,
               config.closed_loop ? "closed loop" : "open loop", elapsed_s, total_s,
               static_cast<unsigned long long>(answered), static_cast<double>(answered - answered_before));
}

}  // namespace

absl::StatusOr<LevelReport> RunLevel(const std::string& target, const StreamPlan& plan, const LevelConfig& config) {
  if (config.concurrency < 1) return absl::InvalidArgumentError("concurrency: must be at least 1");
  if (!config.closed_loop && !(config.rate_per_s > 0.0)) {
    return absl::InvalidArgumentError("rate: open loop needs a positive arrival rate");
  }
  std::vector<std::shared_ptr<grpc::Channel>> channels;
  std::vector<std::unique_ptr<v1::MpcService::Stub>> stubs;
  std::vector<std::unique_ptr<LoadStream>> streams;
  for (int i = 0; i < config.concurrency; ++i) {
    absl::StatusOr<std::shared_ptr<grpc::Channel>> channel = OwnConnection(target, config.security);
    if (!channel.ok()) return channel.status();
    channels.push_back(*std::move(channel));
    stubs.push_back(v1::MpcService::NewStub(channels.back()));
    streams.push_back(std::make_unique<LoadStream>(stubs.back().get(), plan));
    if (const grpc::Status s = streams.back()->Open(); !s.ok()) {
      for (auto& opened : streams) opened->Stop(std::chrono::milliseconds(1000));
      return absl::Status(static_cast<absl::StatusCode>(s.error_code()),
                          absl::StrCat("opening stream ", i + 1, " of ", config.concurrency, ": ", s.error_message()));
    }
  }

  const Clock::time_point start = Clock::now();
  const Clock::time_point measure_from =
      start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(config.warmup_s));
  const Clock::time_point end =
      measure_from + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(config.duration_s));
  for (auto& s : streams) s->BeginMeasuring(measure_from, end);

  std::mt19937_64 rng(config.seed);
  std::exponential_distribution<double> gap_s(config.closed_loop ? 1.0 : config.rate_per_s);
  std::uniform_int_distribution<int> pick(0, config.concurrency - 1);
  Clock::time_point next_arrival = start;
  Clock::time_point next_progress = start + std::chrono::seconds(1);
  std::uint64_t answered_at_last_progress = 0;
  Clock::time_point stopped_at = end;
  for (;;) {
    const Clock::time_point now = Clock::now();
    if (now >= end) break;
    if (config.requests > 0 && Answered(streams) >= config.requests) {
      stopped_at = now;
      break;
    }
    if (config.progress && now >= next_progress) {
      const std::uint64_t answered = Answered(streams);
      PrintProgress(config, Seconds(now - start), config.warmup_s + config.duration_s, answered,
                    answered_at_last_progress);
      answered_at_last_progress = answered;
      next_progress += std::chrono::seconds(1);
    }
    if (config.closed_loop) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      continue;
    }
    // Open loop: send every arrival that is due (in a burst if this thread fell behind:
    // the arrival times stay those of the Poisson process), then sleep until the next.
    while (next_arrival <= now) {
      streams[pick(rng)]->Send(next_arrival);
      next_arrival += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(gap_s(rng)));
    }
    const Clock::time_point wake = std::min({next_arrival, end, next_progress});
    if (wake - Clock::now() > std::chrono::microseconds(100)) std::this_thread::sleep_until(wake);
  }
  for (auto& s : streams) s->Stop(std::chrono::milliseconds(5000));

  LevelReport report;
  report.config = config;
  std::vector<double> answered;
  for (auto& s : streams) {
    StreamTally tally = s->TakeTally();
    answered.push_back(static_cast<double>(tally.latency_ms.size()));
    report.tally.MergeFrom(tally);
  }
  const double mean_answered = std::accumulate(answered.begin(), answered.end(), 0.0) /
                               static_cast<double>(std::max<std::size_t>(1, answered.size()));
  if (mean_answered > 0.0) {
    report.stream_min_share = *std::min_element(answered.begin(), answered.end()) / mean_answered;
    report.stream_max_share = *std::max_element(answered.begin(), answered.end()) / mean_answered;
  }
  report.measured_s = std::max(1e-9, Seconds(std::min(stopped_at, end) - measure_from));
  Summarize(report);
  return report;
}

void Summarize(LevelReport& report) {
  StreamTally& t = report.tally;
  report.solves_per_s = static_cast<double>(t.latency_ms.size()) / report.measured_s;
  report.p50_ms = Quantile(t.latency_ms, 0.50);
  report.p90_ms = Quantile(t.latency_ms, 0.90);
  report.p99_ms = Quantile(t.latency_ms, 0.99);
  report.p999_ms = Quantile(t.latency_ms, 0.999);
  report.max_ms = t.latency_ms.empty() ? 0.0 : *std::max_element(t.latency_ms.begin(), t.latency_ms.end());
  report.service_p50_ms = Quantile(t.service_ms, 0.50);
  report.service_p99_ms = Quantile(t.service_ms, 0.99);
  report.solve_p50_ms = Quantile(t.solve_ms, 0.50);
  report.mean_iterations =
      t.latency_ms.empty() ? 0.0 : static_cast<double>(t.iterations) / static_cast<double>(t.latency_ms.size());
}

LevelReport MergeRounds(const std::vector<LevelReport>& rounds) {
  LevelReport merged;
  if (rounds.empty()) return merged;
  merged.config = rounds.front().config;
  merged.config.duration_s = 0.0;
  merged.stream_min_share = rounds.front().stream_min_share;
  merged.stream_max_share = rounds.front().stream_max_share;
  for (const LevelReport& round : rounds) {
    merged.config.duration_s += round.config.duration_s;
    merged.measured_s += round.measured_s;
    merged.tally.MergeFrom(round.tally);
    // The streams differ between rounds: the least and the most served of any round.
    merged.stream_min_share = std::min(merged.stream_min_share, round.stream_min_share);
    merged.stream_max_share = std::max(merged.stream_max_share, round.stream_max_share);
  }
  Summarize(merged);
  return merged;
}

bool StarvedAStream(const LevelReport& level) {
  if (!level.config.closed_loop || level.config.concurrency < 2) return false;
  const double answers_per_stream = static_cast<double>(level.tally.latency_ms.size()) / level.config.concurrency;
  if (answers_per_stream < kMinAnswersToJudge) return false;
  return level.stream_min_share < 1.0 / kFairShareFactor || level.stream_max_share > kFairShareFactor;
}

}  // namespace nupmpc::loadtest
