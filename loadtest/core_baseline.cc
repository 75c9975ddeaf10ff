#include "loadtest/core_baseline.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/session/session.h"
#include "server/spec_conversion.h"

namespace nupmpc::loadtest {

double Quantile(std::vector<double>& values, double q) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(values.size())));
  return values[std::clamp<std::size_t>(rank, 1, values.size()) - 1];
}

absl::StatusOr<CoreBaseline> MeasureCoreBaseline(const v1::ProblemSpec& spec,
                                                 const std::vector<std::vector<double>>& states, int rounds) {
  server::SizeLimits no_limits;  // the server checks its limits; the baseline solves what it gets
  no_limits.max_states = no_limits.max_inputs = no_limits.max_outputs = 1 << 20;
  no_limits.max_horizon = no_limits.max_iterations = 1 << 30;
  no_limits.max_scalars = 1LL << 40;
  absl::StatusOr<core::Problem> problem = server::ProblemFromSpec(spec, no_limits);
  if (!problem.ok()) return problem.status();
  absl::StatusOr<core::SolverOptions> options = server::OptionsFromSpec(spec.options(), no_limits);
  if (!options.ok()) return options.status();
  absl::StatusOr<std::unique_ptr<core::Session>> session = core::Session::Create(*problem, *options);
  if (!session.ok()) return session.status();

  core::Solution solution;
  std::vector<double> times_ms;
  std::uint64_t iterations = 0;
  for (int round = 0; round < rounds; ++round) {
    for (std::size_t t = 0; t < states.size(); ++t) {
      const Eigen::Map<const Eigen::VectorXd> x(states[t].data(), static_cast<Eigen::Index>(states[t].size()));
      core::SolveLimits limits;
      limits.warm_start = t > 0;
      const auto start = std::chrono::steady_clock::now();
      if (absl::Status s = (*session)->SetInitialState(x); !s.ok()) return s;
      (*session)->ShiftWarmStart();
      absl::StatusOr<core::SolveSummary> summary = (*session)->Solve(limits, &solution);
      const auto stop = std::chrono::steady_clock::now();
      if (!summary.ok()) return summary.status();
      times_ms.push_back(std::chrono::duration<double, std::milli>(stop - start).count());
      iterations += summary->iterations;
    }
  }
  CoreBaseline out;
  out.solves = static_cast<int>(times_ms.size());
  out.mean_iterations = out.solves > 0 ? static_cast<double>(iterations) / out.solves : 0.0;
  out.median_ms = Quantile(times_ms, 0.5);
  out.p99_ms = Quantile(times_ms, 0.99);
  return out;
}

}  // namespace nupmpc::loadtest
