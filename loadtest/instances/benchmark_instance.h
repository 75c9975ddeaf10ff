#ifndef NUPMPC_LOADTEST_INSTANCES_BENCHMARK_INSTANCE_H_
#define NUPMPC_LOADTEST_INSTANCES_BENCHMARK_INSTANCE_H_

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/nupmpc.h"
#include "server/convert/spec_conversion.h"

namespace nupmpc::bench {

// The test data of benchmarks/ for the core benchmarks and the tests, in the
// core's terms. An instance file is read once, by the proto-only reader of the command-line
// tools (client/problem_file.h: the instance as a v1::ProblemSpec and its recorded
// closed-loop states); its core Problem is that spec through the server's conversion
// (server::ProblemFromSpec), so every tool and test solves the problem the service would.

// One instance file in the format of benchmarks/README.md as a core Problem
// (benchmark x_1 = x[0], y_n = y[n-1]; no output prior at step N; R and Qy must be
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

// Size limits that admit any spec (tools and tests solve what they are given; the server
// checks its own limits).
server::SizeLimits NoSizeLimits();

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

#endif  // NUPMPC_LOADTEST_INSTANCES_BENCHMARK_INSTANCE_H_
