#ifndef NUPMPC_LOADTEST_BENCHMARK_INSTANCE_H_
#define NUPMPC_LOADTEST_BENCHMARK_INSTANCE_H_

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/problem.h"

namespace nupmpc::bench {

// One instance file in the format of shared/benchmarks/README.md, converted to a core
// Problem (benchmark x_1 = x[0], y_n = y[n-1]; no output prior at step N; R and Qy must be
// diagonal, since the core's priors are per scalar).
struct BenchmarkInstance {
  std::string name;
  std::string family;
  core::Problem problem;
  struct ClosedLoop {
    std::vector<Eigen::VectorXd> x1;  ///< initial state of each step t = 0..T-1
  };
  std::optional<ClosedLoop> closed_loop;
};

absl::StatusOr<BenchmarkInstance> LoadBenchmarkInstance(const std::string& path);

// One entry of reference.json.
struct Reference {
  double J_star = 0.0;
  double max_violation = 0.0;
  std::optional<Eigen::MatrixXd> u_star;  ///< N × L
  std::optional<Eigen::VectorXd> x1_star;
  std::vector<double> closed_loop_J_star;
  std::vector<Eigen::MatrixXd> closed_loop_u_star;  ///< per step, N × L
};

absl::StatusOr<std::map<std::string, Reference>> LoadReferences(const std::string& path);

}  // namespace nupmpc::bench

#endif  // NUPMPC_LOADTEST_BENCHMARK_INSTANCE_H_
