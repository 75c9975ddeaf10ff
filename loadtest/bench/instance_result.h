#ifndef NUPMPC_LOADTEST_BENCH_INSTANCE_RESULT_H_
#define NUPMPC_LOADTEST_BENCH_INSTANCE_RESULT_H_

#include <cmath>
#include <string>
#include <vector>

namespace nupmpc::bench {

// One instance's line of nupmpc-bench.
struct InstanceResult {
  std::string name;
  std::string algorithm;
  int iterations = 0;
  double solve_ms = 0.0;
  double objective = 0.0;
  double rel_gap = NAN;
  double max_violation = 0.0;
  std::string status;
  bool polished = false;
  double gflops = NAN;
  double flops_per_iteration = 0.0;
  int N = 0;
};

// The median (NaN when empty).
double Median(std::vector<double> v);

// A number for the JSON lines: JSON has no NaN, absent figures are null.
std::string Num(double v);

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_BENCH_INSTANCE_RESULT_H_
