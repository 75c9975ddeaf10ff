#ifndef NUPMPC_LOADTEST_BENCH_BENCH_REPORT_H_
#define NUPMPC_LOADTEST_BENCH_BENCH_REPORT_H_

#include <string>
#include <vector>

#include "core/nupmpc.h"

namespace nupmpc::bench {

struct BenchOptions {
  bool json = false;
  std::string reference;  ///< empty: reference.json beside each instance file
  core::Algorithm algorithm = core::Algorithm::kAuto;
  int repeat = 5;
  int max_iterations = 5000;
  bool scaling = false;
  bool trace = false;
  int polish_after = 1;
  bool interior_point = true;
  int polish_rounds = 4;
};

// Solves every file and prints one line (table row or JSON object) per instance, then the
// closed-loop, scaling and efficiency figures. Returns the process exit code.
int RunBenchmarks(const std::vector<std::string>& paths, const BenchOptions& options);

// Floating-point operations of one iteration of `algorithm` on `problem` (the recursions
// of nup-algorithms.md §3, §8, §9 as implemented, dense matrix products counted as 2mnk).
double FlopsPerIteration(const core::Problem& problem, core::Algorithm algorithm);

// Double-precision GEMM rate of this machine for n×n matrices (Eigen, one thread), GFLOP/s.
double MeasureGemmGflops(int n);

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_BENCH_BENCH_REPORT_H_
