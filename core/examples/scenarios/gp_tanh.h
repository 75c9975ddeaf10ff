#ifndef NUPMPC_CORE_EXAMPLES_SCENARIOS_GP_TANH_H_
#define NUPMPC_CORE_EXAMPLES_SCENARIOS_GP_TANH_H_

// The example of [Nghiem] §V: plant x[k] = x[k-1] - 0.5 tanh(x[k-1] + u[k]³), y = x + w
// (u[k] is the input applied between samples k-1 and k, the paper's (21a) indexing),
// w ~ N(0, 0.025²), u ∈ [-1, 1], Δu ∈ [-0.5, 0.5]; a GP on the regressor [y[k-1], u[k]];
// MPC (21) with H = 12, Q = 10, R = 0.1, δ = 0.075, chance-constraint bounds ±1.2 with 2σ;
// 100 closed-loop steps tracking -0.5 (k ≤ 50), then -0.2.

#include <cstdint>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/gp/gp_model.h"
#include "core/gp/lingp_scp.h"
#include "core/gp/narx.h"

namespace nupmpc::examples {

constexpr double kTanhNoiseStd = 0.025;

double TanhPlantStep(double x, double u);

// A logged experiment of `samples` steps: a random input that respects the constraints
// (a random walk with steps uniform in the rate limits, kept in the box), the plant from
// x = 0, noisy outputs. Deterministic for a seed.
struct TanhExperiment {
  Eigen::VectorXd y, u;
};
TanhExperiment RunTanhExperiment(int samples, std::uint32_t seed);

// The NARX layout [y[k-1], u[k]] and the MPC problem (21).
gp::NarxLayout TanhLayout();
gp::GpMpcProblem TanhMpcProblem();

// Training data for N points (the experiment's first N + 1 samples).
absl::StatusOr<gp::NarxData> TanhTrainingData(int points, std::uint32_t seed);

// The reference of [Nghiem] §V at step k (0-based): -0.5 for k ≤ 50, -0.2 after.
double TanhReference(int k);

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_SCENARIOS_GP_TANH_H_
