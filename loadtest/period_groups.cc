#include "loadtest/period_groups.h"

#include <algorithm>
#include <atomic>
#include <memory>
#include <mutex>
#include <numeric>
#include <thread>

#include "absl/strings/str_format.h"
#include "client/client.h"
#include "loadtest/quantile.h"

namespace nupmpc::loadtest {
namespace {

using Clock = std::chrono::steady_clock;

// One stream's count, merged into its group's after the run.
struct StreamCount {
  GroupFigures figures;
  std::vector<double> slack_ms;
};

void Count(const absl::StatusOr<v1::SolveResult>& result, StreamCount* count) {
  GroupFigures& f = count->figures;
  ++f.steps;
  if (!result.ok()) {
    ++f.errors;
    return;
  }
  if (result->status() == v1::SOLVE_STATUS_HELD) {
    ++f.held;
    return;
  }
  if (result->deadline() != v1::DEADLINE_OUTCOME_UNSPECIFIED) count->slack_ms.push_back(result->deadline_slack_ms());
  switch (result->deadline()) {
    case v1::DEADLINE_OUTCOME_MET:
      if (result->has_plan()) {
        ++f.met;
      } else {
        ++f.other;
      }
      break;
    case v1::DEADLINE_OUTCOME_QUEUED_PAST_DEADLINE:
      ++f.queued_past_deadline;
      break;
    case v1::DEADLINE_OUTCOME_SOLVE_TOO_LONG:
      ++f.solve_too_long;
      break;
    default:
      ++f.other;  // superseded (no deadline outcome), or a server without deadlines
      break;
  }
}

}  // namespace

absl::StatusOr<std::vector<GroupFigures>> RunPeriodGroups(const std::string& target,
                                                          const std::vector<PeriodGroup>& groups,
                                                          std::chrono::milliseconds duration,
                                                          std::chrono::milliseconds warmup) {
  struct Stream {
    const PeriodGroup* group = nullptr;
    std::unique_ptr<Client> client;
    std::unique_ptr<Session> session;
    StreamCount count;
  };
  std::vector<Stream> streams;
  for (const PeriodGroup& group : groups) {
    for (int s = 0; s < group.streams; ++s) {
      Stream stream;
      stream.group = &group;
      stream.client = std::make_unique<Client>(target);  // a connection of its own
      absl::StatusOr<std::unique_ptr<Session>> session =
          stream.client->OpenSession(group.spec, {}, ControlPeriod{.period = group.period});
      if (!session.ok()) return session.status();
      stream.session = *std::move(session);
      streams.push_back(std::move(stream));
    }
  }
  const Clock::time_point start = Clock::now() + std::chrono::milliseconds(100);
  const Clock::time_point counted_from = start + warmup, until = counted_from + duration;
  std::vector<std::thread> threads;
  threads.reserve(streams.size());
  for (std::size_t i = 0; i < streams.size(); ++i) {
    threads.emplace_back([&, i] {
      Stream& stream = streams[i];
      const PeriodGroup& group = *stream.group;
      // Streams of a group start spread over one period and over the states they cycle
      // through, as independent controllers would: in step, every stream would meet the
      // costly steps of the cycle (its start, its jump back) in the same period, a burst
      // of work no fleet of separate plants produces.
      const std::size_t in_group = i % static_cast<std::size_t>(group.streams);
      const auto group_size = static_cast<std::size_t>(std::max(group.streams, 1));
      Clock::time_point next = start + group.period * static_cast<long>(in_group) / static_cast<long>(group_size);
      for (std::size_t t = in_group * group.states.size() / group_size; next < until; ++t) {
        std::this_thread::sleep_until(next);
        const Clock::time_point began = Clock::now();
        v1::Step step;
        const std::vector<double>& x = group.states[t % group.states.size()];
        step.mutable_state()->Add(x.begin(), x.end());
        const absl::StatusOr<v1::SolveResult> result = stream.session->Step(step);
        if (began >= counted_from) Count(result, &stream.count);
        next = std::max(next + group.period, Clock::now());  // paced: never a burst to catch up
      }
    });
  }
  for (std::thread& t : threads) t.join();
  for (Stream& stream : streams) (void)stream.session->Close();

  std::vector<GroupFigures> out;
  for (const PeriodGroup& group : groups) {
    GroupFigures f;
    f.name = group.name;
    f.streams = group.streams;
    f.period_ms = std::chrono::duration<double, std::milli>(group.period).count();
    std::vector<double> slack;
    std::vector<double> met;
    for (const Stream& stream : streams) {
      if (stream.group != &group) continue;
      const GroupFigures& c = stream.count.figures;
      f.steps += c.steps;
      f.met += c.met;
      f.queued_past_deadline += c.queued_past_deadline;
      f.solve_too_long += c.solve_too_long;
      f.held += c.held;
      f.other += c.other;
      f.errors += c.errors;
      slack.insert(slack.end(), stream.count.slack_ms.begin(), stream.count.slack_ms.end());
      met.push_back(static_cast<double>(c.met));
    }
    f.slack_p50_ms = Quantile(slack, 0.5);
    f.slack_p01_ms = Quantile(slack, 0.01);
    const double mean =
        met.empty() ? 0.0 : std::accumulate(met.begin(), met.end(), 0.0) / static_cast<double>(met.size());
    if (mean > 0.0) {
      f.stream_min_share = *std::min_element(met.begin(), met.end()) / mean;
      f.stream_max_share = *std::max_element(met.begin(), met.end()) / mean;
    }
    out.push_back(f);
  }
  return out;
}

absl::StatusOr<double> CalibrateStepsPerSecond(const std::string& target, const PeriodGroup& group,
                                               std::chrono::milliseconds duration, int streams) {
  std::vector<std::unique_ptr<Client>> clients;
  std::vector<std::unique_ptr<Session>> sessions;
  clients.reserve(static_cast<std::size_t>(streams));
  sessions.reserve(static_cast<std::size_t>(streams));
  for (int s = 0; s < streams; ++s) {
    clients.push_back(std::make_unique<Client>(target));
    absl::StatusOr<std::unique_ptr<Session>> session = clients.back()->OpenSession(group.spec);
    if (!session.ok()) return session.status();
    sessions.push_back(*std::move(session));
  }
  const Clock::time_point from = Clock::now() + std::chrono::milliseconds(300);  // warm first
  const Clock::time_point until = from + duration;
  std::atomic<long> steps{0};
  std::atomic<bool> failed{false};
  std::vector<std::thread> threads;
  threads.reserve(static_cast<std::size_t>(streams));
  for (int s = 0; s < streams; ++s) {
    threads.emplace_back([&, s] {
      for (std::size_t t = 0; Clock::now() < until && !failed.load(); ++t) {
        v1::Step step;
        const std::vector<double>& x = group.states[t % group.states.size()];
        step.mutable_state()->Add(x.begin(), x.end());
        if (!sessions[static_cast<std::size_t>(s)]->Step(step).ok()) failed.store(true);
        if (Clock::now() >= from && Clock::now() < until) steps.fetch_add(1);
      }
    });
  }
  for (std::thread& t : threads) t.join();
  for (const std::unique_ptr<Session>& session : sessions) (void)session->Close();
  if (failed.load()) return absl::UnavailableError("a calibration step failed");
  return static_cast<double>(steps.load()) / std::chrono::duration<double>(duration).count();
}

std::string GroupFiguresJson(const GroupFigures& f) {
  return absl::StrFormat(
      "{\"group\":\"%s\",\"streams\":%d,\"period_ms\":%.3f,\"steps\":%d,\"met\":%d,\"missed\":%d,"
      "\"missed_by_cause\":{\"queued_past_deadline\":%d,\"solve_too_long\":%d,\"held\":%d,\"other\":%d,\"errors\":%d},"
      "\"missed_share\":%.6f,\"slack_p50_ms\":%.4f,\"slack_p01_ms\":%.4f,\"stream_min_share\":%.4f,"
      "\"stream_max_share\":%.4f}",
      f.name, f.streams, f.period_ms, f.steps, f.met, f.steps - f.met, f.queued_past_deadline, f.solve_too_long, f.held,
      f.other, f.errors, f.missed_share(), f.slack_p50_ms, f.slack_p01_ms, f.stream_min_share, f.stream_max_share);
}

}  // namespace nupmpc::loadtest
