#include "loadtest/bench/bench_report.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>

#include "Eigen/Core"
#include "absl/strings/str_format.h"
#include "core/public/session.h"
#include "loadtest/bench/instance_result.h"
#include "loadtest/bench/pass_trace.h"
#include "loadtest/bench/scaling_report.h"
#include "loadtest/instances/benchmark_instance.h"

namespace nupmpc::bench {
namespace {

using Clock = std::chrono::steady_clock;

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(std::ceil(q * v.size())) - 1);
  return v[i];
}

std::string ReferencePath(const std::string& instance_path, const BenchOptions& options) {
  if (!options.reference.empty()) return options.reference;
  return (std::filesystem::path(instance_path).parent_path() / "reference.json").string();
}

struct ClosedLoopResult {
  int steps = 0;
  double warm_median_ms = 0, warm_p99_ms = 0, cold_median_ms = 0, cold_p99_ms = 0;
  double warm_median_iterations = 0, cold_median_iterations = 0;
  int warm_max_iterations = 0;
  double max_abs_gap = NAN;
};

ClosedLoopResult RunClosedLoop(const BenchmarkInstance& inst, const core::SolverOptions& solver_options,
                               const Reference* ref) {
  ClosedLoopResult out;
  auto warm = core::Session::Create(inst.problem, solver_options);
  auto cold = core::Session::Create(inst.problem, solver_options);
  if (!warm.ok() || !cold.ok()) return out;
  std::vector<double> warm_ms, cold_ms, warm_it, cold_it;
  core::Solution solution;
  const auto& x1 = inst.closed_loop->x1;
  out.steps = static_cast<int>(x1.size());
  for (std::size_t t = 0; t < x1.size(); ++t) {
    (*warm)->ShiftWarmStart();
    (void)(*warm)->SetInitialState(x1[t]);
    const auto t0 = Clock::now();
    absl::StatusOr<core::SolveSummary> w = (*warm)->Solve(&solution);
    warm_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    (void)(*cold)->SetInitialState(x1[t]);
    core::SolveLimits cold_limits;
    cold_limits.warm_start = false;
    const auto t1 = Clock::now();
    absl::StatusOr<core::SolveSummary> c = (*cold)->Solve(cold_limits, nullptr);
    cold_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t1).count());
    if (!w.ok() || !c.ok()) continue;
    warm_it.push_back(w->iterations);
    cold_it.push_back(c->iterations);
    out.warm_max_iterations = std::max(out.warm_max_iterations, w->iterations);
    if (ref != nullptr && t < ref->closed_loop_J_star.size()) {
      const double gap = std::abs(w->objective - ref->closed_loop_J_star[t]) / std::abs(ref->closed_loop_J_star[t]);
      out.max_abs_gap = std::isnan(out.max_abs_gap) ? gap : std::max(out.max_abs_gap, gap);
    }
  }
  out.warm_median_ms = Median(warm_ms);
  out.warm_p99_ms = Percentile(warm_ms, 0.99);
  out.cold_median_ms = Median(cold_ms);
  out.cold_p99_ms = Percentile(cold_ms, 0.99);
  out.warm_median_iterations = Median(warm_it);
  out.cold_median_iterations = Median(cold_it);
  return out;
}

}  // namespace

double FlopsPerIteration(const core::Problem& p, core::Algorithm algorithm) {
  const double N = p.horizon, L = p.num_inputs, K = p.num_outputs;
  const double terminal = p.terminal.has_value() ? p.num_states : 0;
  bool inputs_constrained = false;
  for (const auto& prior : p.input_priors) inputs_constrained |= prior.kind != core::PriorKind::kNone;
  const bool augmented = algorithm == core::Algorithm::kIffbdd && inputs_constrained;
  const double M = p.num_states + (augmented ? L : 0);
  const double rows = K + (augmented ? L : 0);
  // Forward Kalman filter: A V Aᵀ (2 products), B diag(VU) Bᵀ, per row V c and the rank-1 update.
  const double filter =
      N * (4 * M * M * M + 2 * M * M * L + 2 * M * L + rows * (4 * M * M + 6 * M)) + terminal * (4 * M * M + 6 * M);
  switch (algorithm) {
    case core::Algorithm::kIffbdd:
      // Backward dual deciding: per row vᵀx̃ and x̃ += c ỹ; per step Aᵀx̃ and the inputs.
      return filter + N * (rows * 4 * M + 2 * M * M + 2 * M * L);
    case core::Algorithm::kIake:
      // MBF means: mX = m⁺ - V⁺ ξ̃, per row updates, inputs, Aᵀ ξ̃.
      return filter + N * (2 * M * M + rows * 6 * M + 4 * M * L + 2 * M * M);
    case core::Algorithm::kIbffd:
      // Backward information filter (Aᵀ W A, rows, inputs) + forward deciding (recomputed
      // per-input messages, one W b per input, the state update).
      return N * (4 * M * M * M + K * 4 * M * M + L * 4 * M * M) + N * (L * 4 * M * M + L * 2 * M * M + 2 * M * M);
    case core::Algorithm::kAuto:
      break;
  }
  return NAN;
}

double MeasureGemmGflops(int n) {
  Eigen::MatrixXd a = Eigen::MatrixXd::Random(n, n), b = Eigen::MatrixXd::Random(n, n), c(n, n);
  int reps = 1;
  double seconds = 0.0;
  while (true) {
    const auto t0 = Clock::now();
    for (int i = 0; i < reps; ++i) {
      c.noalias() = a * b;
      a(0, 0) += 1e-300 * c(0, 0);  // keep the loop honest
    }
    seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    if (seconds > 0.2) break;
    reps *= 2;
  }
  return 2.0 * n * n * n * reps / seconds * 1e-9;
}

int RunBenchmarks(const std::vector<std::string>& paths, const BenchOptions& options) {
  std::map<std::string, std::map<std::string, Reference>> reference_files;
  int failures = 0;
  std::vector<InstanceResult> results;
  std::vector<ScalingEntry> scaling;
  // The per-stage kernels work on M×M blocks: the machine's GEMM rate at the benchmarks'
  // state sizes (masses 12, random_outbox 40) is what their flop rate compares with.
  const double gemm12 = MeasureGemmGflops(12), gemm20 = MeasureGemmGflops(20), gemm40 = MeasureGemmGflops(40);
  if (!options.json) {
    std::printf("machine: Eigen double GEMM (one thread) n=12 %.1f, n=20 %.1f, n=40 %.1f GFLOP/s\n\n", gemm12, gemm20,
                gemm40);
    std::printf("%-36s %-7s %6s %10s %20s %10s %10s %-16s %8s\n", "instance", "algo", "iter", "solve_ms", "objective",
                "rel_gap", "max_viol", "status", "GFLOP/s");
  }
  for (const std::string& path : paths) {
    if (std::filesystem::path(path).filename() == "reference.json") continue;  // not an instance
    absl::StatusOr<BenchmarkInstance> inst = LoadBenchmarkInstance(path);
    if (!inst.ok()) {
      std::fprintf(stderr, "nupmpc-bench: %s\n", std::string(inst.status().message()).c_str());
      ++failures;
      continue;
    }
    const std::string ref_path = ReferencePath(path, options);
    if (!reference_files.count(ref_path)) {
      absl::StatusOr<std::map<std::string, Reference>> refs = LoadReferences(ref_path);
      reference_files[ref_path] = refs.ok() ? *refs : std::map<std::string, Reference>{};
    }
    const auto& refs = reference_files[ref_path];
    const Reference* ref = refs.count(inst->name) ? &refs.at(inst->name) : nullptr;

    core::SolverOptions solver_options;
    solver_options.algorithm = options.algorithm;
    solver_options.max_iterations = options.max_iterations;
    solver_options.polish_after_stable_iterations = options.polish_after;
    solver_options.interior_point = options.interior_point;
    solver_options.polish_rounds = options.polish_rounds;
    absl::StatusOr<std::unique_ptr<core::Session>> session = core::Session::Create(inst->problem, solver_options);
    if (!session.ok()) {
      std::fprintf(stderr, "nupmpc-bench: %s: %s\n", inst->name.c_str(),
                   std::string(session.status().message()).c_str());
      ++failures;
      continue;
    }
    std::vector<double> times;
    core::SolveSummary summary;
    core::SolveLimits cold;
    cold.warm_start = false;
    for (int r = 0; r < options.repeat; ++r) {
      const auto t0 = Clock::now();
      absl::StatusOr<core::SolveSummary> s = (*session)->Solve(cold, nullptr);
      times.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      if (!s.ok()) {
        std::fprintf(stderr, "nupmpc-bench: %s: %s\n", inst->name.c_str(), std::string(s.status().message()).c_str());
        ++failures;
        break;
      }
      summary = *s;
    }
    InstanceResult res;
    res.name = inst->name;
    res.algorithm = core::AlgorithmName(summary.algorithm);
    res.iterations = summary.iterations;
    res.solve_ms = Median(times);
    res.objective = summary.objective;
    res.max_violation = summary.max_violation;
    res.status = core::SolveStatusName(summary.status);
    res.polished = summary.polished;
    res.N = inst->problem.horizon;
    if (ref != nullptr) res.rel_gap = (summary.objective - ref->J_star) / std::abs(ref->J_star);
    res.flops_per_iteration = FlopsPerIteration(inst->problem, summary.algorithm);
    res.gflops = res.flops_per_iteration * summary.iterations / (res.solve_ms * 1e-3) * 1e-9;
    results.push_back(res);

    std::optional<ClosedLoopResult> cl;
    if (inst->closed_loop.has_value()) cl = RunClosedLoop(*inst, solver_options, ref);

    if (options.json) {
      std::string line = absl::StrFormat(
          "{\"name\":\"%s\",\"algorithm\":\"%s\",\"iterations\":%d,\"solve_ms\":%s,\"objective\":%s,"
          "\"rel_gap\":%s,\"max_violation\":%s,\"status\":\"%s\",\"polished\":%s,\"gflops\":%s,"
          "\"gemm40_gflops\":%s",
          res.name, res.algorithm, res.iterations, Num(res.solve_ms), Num(res.objective), Num(res.rel_gap),
          Num(res.max_violation), res.status, res.polished ? "true" : "false", Num(res.gflops), Num(gemm40));
      if (cl.has_value()) {
        line += absl::StrFormat(
            ",\"closed_loop\":{\"steps\":%d,\"warm_median_ms\":%s,\"warm_p99_ms\":%s,\"cold_median_ms\":%s,"
            "\"cold_p99_ms\":%s,\"warm_median_iterations\":%s,\"warm_max_iterations\":%d,"
            "\"cold_median_iterations\":%s,\"max_abs_rel_gap\":%s}",
            cl->steps, Num(cl->warm_median_ms), Num(cl->warm_p99_ms), Num(cl->cold_median_ms), Num(cl->cold_p99_ms),
            Num(cl->warm_median_iterations), cl->warm_max_iterations, Num(cl->cold_median_iterations),
            Num(cl->max_abs_gap));
      }
      std::printf("%s}\n", line.c_str());
    } else {
      std::printf("%-36s %-7s %6d %10.4f %20.12g %10.2e %10.2e %-16s %8.2f\n", res.name.c_str(), res.algorithm.c_str(),
                  res.iterations, res.solve_ms, res.objective, res.rel_gap, res.max_violation,
                  (res.status + (res.polished ? "+polish" : "")).c_str(), res.gflops);
      if (cl.has_value()) {
        std::printf(
            "  closed loop (%d steps): warm median %.4f ms (p99 %.4f), %.0f it (max %d) | cold median %.4f ms "
            "(p99 %.4f), %.0f it | max |gap| %.2e\n",
            cl->steps, cl->warm_median_ms, cl->warm_p99_ms, cl->warm_median_iterations, cl->warm_max_iterations,
            cl->cold_median_ms, cl->cold_p99_ms, cl->cold_median_iterations, cl->max_abs_gap);
      }
    }
    if (options.trace) PrintPassTrace(inst->name, **session, options.json);
    std::fflush(stdout);
    if (options.scaling && res.name.rfind("masses_N", 0) == 0) {
      scaling.push_back(ScalingEntry{std::move(*session), results.size() - 1});
    }
  }
  if (options.scaling) {
    MeasureInterleaved(scaling, options.repeat, results);
    std::vector<const InstanceResult*> masses;
    for (const auto& r : results) {
      if (r.name.rfind("masses_N", 0) == 0) masses.push_back(&r);
    }
    if (!options.json) {
      std::printf("\nscaling (time per horizon step and per iteration-step; solved interleaved, %d rounds):\n",
                  options.repeat);
    }
    PrintScaling(masses, 12, gemm12, options.json);
    failures += RunGeneratedScaling(options, gemm40);
    failures += RunKernelRates(options, gemm20, gemm40);
  }
  return failures == 0 ? 0 : 1;
}

}  // namespace nupmpc::bench
