#include "loadtest/bench/scaling_report.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>

#include "absl/strings/str_format.h"
#include "loadtest/bench/random_output_box.h"

namespace nupmpc::bench {

using Clock = std::chrono::steady_clock;

void MeasureInterleaved(std::vector<ScalingEntry>& entries, int rounds, std::vector<InstanceResult>& results) {
  std::vector<std::vector<double>> times(entries.size());
  core::SolveLimits cold;
  cold.warm_start = false;
  for (int round = 0; round < rounds; ++round) {
    for (std::size_t k = 0; k < entries.size(); ++k) {
      const std::size_t e = round % 2 == 0 ? k : entries.size() - 1 - k;
      const auto t0 = Clock::now();
      const absl::StatusOr<core::SolveSummary> s = entries[e].session->Solve(cold, nullptr);
      if (s.ok()) times[e].push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    }
  }
  for (std::size_t e = 0; e < entries.size(); ++e) {
    if (times[e].empty()) continue;
    InstanceResult& r = results[entries[e].result];
    r.solve_ms = Median(times[e]);
    r.gflops = r.flops_per_iteration * r.iterations / (r.solve_ms * 1e-3) * 1e-9;
  }
}

void PrintScaling(std::vector<const InstanceResult*> rows, int gemm_n, double gemm, bool json) {
  std::sort(rows.begin(), rows.end(), [](auto* a, auto* b) { return a->N < b->N; });
  const auto per_step_us = [](const InstanceResult& r) { return r.solve_ms * 1e3 / r.N; };
  const auto per_it_step_ns = [](const InstanceResult& r) {
    return r.solve_ms * 1e6 / (static_cast<double>(r.N) * r.iterations);
  };
  double base_us = NAN, base_ns = NAN;
  for (const InstanceResult* r : rows) {
    if (r->N == 300) base_us = per_step_us(*r), base_ns = per_it_step_ns(*r);
  }
  for (const InstanceResult* r : rows) {
    const double us = per_step_us(*r), ns = per_it_step_ns(*r);
    if (json) {
      std::printf(
          "{\"scaling\":\"%s\",\"N\":%d,\"iterations\":%d,\"us_per_step\":%s,\"ns_per_iteration_step\":%s,"
          "\"per_step_vs_N300\":%s,\"per_iteration_step_vs_N300\":%s,\"gflops\":%s,\"gemm_n\":%d,"
          "\"gemm_gflops\":%s}\n",
          r->name.c_str(), r->N, r->iterations, Num(us).c_str(), Num(ns).c_str(), Num(us / base_us).c_str(),
          Num(ns / base_ns).c_str(), Num(r->gflops).c_str(), gemm_n, Num(gemm).c_str());
    } else {
      std::printf(
          "  %-34s N=%6d  %9.3f us/step (%4.2fx N=300)  %9.1f ns/(iteration*step) (%4.2fx)  (%d iterations)  "
          "%6.2f GFLOP/s (%.0f %% of GEMM n=%d)\n",
          r->name.c_str(), r->N, us, us / base_us, ns, ns / base_ns, r->iterations, r->gflops, 100.0 * r->gflops / gemm,
          gemm_n);
    }
  }
}

namespace {

// A generated random output box (M, K, L, N; seed 1) solved cold once with `solver_options`:
// its description in `r` (the pass count the timed solves divide by) and its session, kept
// to be solved again. Null, after a message on stderr, when it fails.
std::unique_ptr<core::Session> SolveGeneratedOnce(int M, int K, int L, int N, const core::SolverOptions& solver_options,
                                                  InstanceResult* r) {
  const core::Problem problem = MakeRandomOutputBox(M, K, L, N, /*seed=*/1);
  absl::StatusOr<std::unique_ptr<core::Session>> session = core::Session::Create(problem, solver_options);
  core::SolveLimits cold;
  cold.warm_start = false;
  absl::StatusOr<core::SolveSummary> s =
      session.ok() ? (*session)->Solve(cold, nullptr) : absl::StatusOr<core::SolveSummary>(session.status());
  if (!s.ok()) {
    std::fprintf(stderr, "nupmpc-bench: generated random output box M=%d N=%d: %s\n", M, N,
                 std::string(s.status().message()).c_str());
    return nullptr;
  }
  r->name = absl::StrFormat("random_output_box_M%d_K%d_L%d (gen.)", M, K, L);
  r->algorithm = core::AlgorithmName(s->algorithm);
  r->iterations = s->iterations;
  r->objective = s->objective;
  r->max_violation = s->max_violation;
  r->status = core::SolveStatusName(s->status);
  r->N = N;
  r->flops_per_iteration = FlopsPerIteration(problem, s->algorithm);
  return *std::move(session);
}

}  // namespace

int RunKernelRates(const BenchOptions& options, double gemm20, double gemm40) {
  struct Shape {
    int M, K, L;
    double gemm;
  };
  const Shape shapes[] = {{20, 10, 10, gemm20}, {40, 20, 20, gemm40}};
  constexpr int kN = 300;
  std::vector<InstanceResult> results;
  std::vector<const Shape*> result_shape;  ///< parallel to results
  std::vector<ScalingEntry> entries;
  int failures = 0;
  for (const Shape& shape : shapes) {
    core::SolverOptions solver_options;
    solver_options.algorithm = core::Algorithm::kIffbdd;
    solver_options.max_iterations = options.max_iterations;
    solver_options.interior_point = false;  // every pass a full filter pass and a costate sweep
    InstanceResult r;
    std::unique_ptr<core::Session> session = SolveGeneratedOnce(shape.M, shape.K, shape.L, kN, solver_options, &r);
    if (session == nullptr) {
      ++failures;
      continue;
    }
    results.push_back(r);
    result_shape.push_back(&shape);
    entries.push_back(ScalingEntry{std::move(session), results.size() - 1});
  }
  MeasureInterleaved(entries, options.repeat, results);
  for (std::size_t i = 0; i < results.size(); ++i) {
    const InstanceResult& r = results[i];
    const int M = result_shape[i]->M;
    const double gemm = result_shape[i]->gemm;
    if (options.json) {
      std::printf(
          "{\"kernel_rate\":\"%s\",\"N\":%d,\"iterations\":%d,\"gflops\":%s,\"gemm_n\":%d,\"gemm_gflops\":%s}\n",
          r.name.c_str(), r.N, r.iterations, Num(r.gflops).c_str(), M, Num(gemm).c_str());
    } else {
      std::printf("  per-stage kernels, %s N=%d, IFFBDD's passes (%d): %.2f GFLOP/s = %.0f %% of GEMM n=%d\n",
                  r.name.c_str(), r.N, r.iterations, r.gflops, 100.0 * r.gflops / gemm, M);
    }
  }
  return failures;
}

int RunGeneratedScaling(const BenchOptions& options, double gemm40) {
  constexpr int kM = 40, kK = 20, kL = 20;
  std::vector<InstanceResult> results;
  std::vector<ScalingEntry> entries;
  results.reserve(3);
  int failures = 0;
  for (const int N : {300, 3000, 30000}) {
    core::SolverOptions solver_options;
    solver_options.algorithm = options.algorithm;
    solver_options.max_iterations = options.max_iterations;
    solver_options.interior_point = options.interior_point;
    InstanceResult r;
    std::unique_ptr<core::Session> session = SolveGeneratedOnce(kM, kK, kL, N, solver_options, &r);
    if (session == nullptr) {
      ++failures;
      continue;
    }
    results.push_back(r);
    entries.push_back(ScalingEntry{std::move(session), results.size() - 1});
    if (!options.json) {
      std::printf("  (generated N=%d: %s, %d iterations, status %s, max violation %.2e)\n", N, r.algorithm.c_str(),
                  r.iterations, r.status.c_str(), r.max_violation);
    }
  }
  // A solve at N = 30000 takes seconds: at most three rounds.
  MeasureInterleaved(entries, std::min(options.repeat, 3), results);
  std::vector<const InstanceResult*> rows;
  rows.reserve(results.size());
  for (const InstanceResult& r : results) rows.push_back(&r);
  PrintScaling(rows, kM, gemm40, options.json);
  return failures;
}

}  // namespace nupmpc::bench
