#include "loadtest/core_baseline.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/nupmpc.h"
#include "loadtest/instances/benchmark_instance.h"
#include "loadtest/load_stream.h"
#include "loadtest/quantile.h"
#include "loadtest/step_as_server.h"
#include "server/sessions/session_factory.h"

namespace nupmpc::loadtest {

absl::StatusOr<CoreBaseline> MeasureCoreBaseline(const v1::ProblemSpec& spec,
                                                 const std::vector<std::vector<double>>& states, int rounds,
                                                 bool new_references, int sessions) {
  // The sessions the server builds for this spec (Δu, multi-level, keep-out and GP specs
  // included), without admission limits: the server checks its own; the baseline solves
  // what it gets.
  std::vector<server::BuiltSession> built;
  for (int s = 0; s < std::max(1, sessions); ++s) {
    absl::StatusOr<server::BuiltSession> session = server::BuildSession(spec, bench::NoSizeLimits());
    if (!session.ok()) return session.status();
    built.push_back(*std::move(session));
  }

  core::Solution solution;
  std::vector<double> times_ms;
  std::vector<std::vector<double>> state_times_ms(states.size());
  std::uint64_t iterations = 0;
  v1::Step message;
  std::uint64_t sequence = 1;  // as a stream numbers its requests
  for (int round = 0; round < rounds; ++round) {
    for (std::size_t t = 0; t < states.size(); ++t, ++sequence) {
      message.mutable_state()->Assign(states[t].begin(), states[t].end());
      // Each round from a cold start, as a stream restarts its states.
      message.set_warm_start(t == 0 ? v1::WARM_START_COLD : v1::WARM_START_UNSPECIFIED);
      if (new_references) *message.mutable_update() = MovingReferences(spec, sequence);
      for (server::BuiltSession& session : built) {
        const auto start = std::chrono::steady_clock::now();
        absl::StatusOr<core::SolveSummary> summary = StepAsTheServerDoes(session, message, &solution);
        const auto stop = std::chrono::steady_clock::now();
        if (!summary.ok()) return summary.status();
        times_ms.push_back(std::chrono::duration<double, std::milli>(stop - start).count());
        state_times_ms[t].push_back(times_ms.back());
        iterations += summary->iterations;
      }
    }
  }
  CoreBaseline out;
  out.solves = static_cast<int>(times_ms.size());
  out.mean_iterations = out.solves > 0 ? static_cast<double>(iterations) / out.solves : 0.0;
  for (double t : times_ms) out.mean_ms += t / static_cast<double>(times_ms.size());
  for (std::vector<double>& t : state_times_ms) out.state_ms.push_back(Quantile(t, 0.5));
  out.median_ms = Quantile(times_ms, 0.5);
  out.p99_ms = Quantile(times_ms, 0.99);
  return out;
}

absl::StatusOr<FleetCoreBaseline> MeasureFleetCore(const v1::ProblemSpec& spec,
                                                   const std::vector<std::vector<double>>& states, int sessions,
                                                   int periods, int first_period) {
  if (sessions < 1 || periods < 1 || first_period < 1) {
    return absl::InvalidArgumentError("a fleet baseline needs a session, a timed period, and a period before it");
  }
  std::vector<server::BuiltSession> fleet;
  for (int s = 0; s < sessions; ++s) {
    absl::StatusOr<server::BuiltSession> built = server::BuildSession(spec, bench::NoSizeLimits());
    if (!built.ok()) return built.status();
    fleet.push_back(*std::move(built));
  }
  core::Solution solution;
  v1::Step message;
  std::uint64_t iterations = 0;
  auto start = std::chrono::steady_clock::now();
  const int cold = first_period - 1;
  for (int period = cold; period < first_period + periods; ++period) {
    if (period == first_period) {  // the cold period is not timed
      iterations = 0;
      start = std::chrono::steady_clock::now();
    }
    for (int s = 0; s < sessions; ++s) {
      const std::vector<double>& x =
          states[(static_cast<std::size_t>(period) + 7 * static_cast<std::size_t>(s)) % states.size()];
      message.mutable_state()->Assign(x.begin(), x.end());
      message.set_warm_start(period == cold ? v1::WARM_START_COLD : v1::WARM_START_UNSPECIFIED);
      absl::StatusOr<core::SolveSummary> summary =
          StepAsTheServerDoes(fleet[static_cast<std::size_t>(s)], message, &solution);
      if (!summary.ok()) return summary.status();
      iterations += summary->iterations;
    }
  }
  const double total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  const double steps = std::max(1, sessions * periods);
  return FleetCoreBaseline{.mean_ms = total_ms / steps, .mean_iterations = static_cast<double>(iterations) / steps};
}

}  // namespace nupmpc::loadtest
