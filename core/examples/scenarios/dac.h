#ifndef NUPMPC_CORE_EXAMPLES_SCENARIOS_DAC_H_
#define NUPMPC_CORE_EXAMPLES_SCENARIOS_DAC_H_

// Digital-to-analog conversion with a binary input ([KL] §V-A, nup-algorithms.md §7):
// the third-order filter (85) as printed (DC gain 0.8967, relative degree 3: u[n] first
// shows in y[n+3]), input in {0, 1}, output tracking a target with Gaussian variance V_Y.

#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/nupmpc.h"

namespace nupmpc::examples {

inline constexpr double kDacSamplePeriod = 0.003;  ///< 3 ms

// Horizon K, one input and one output, priors all free; x[0] is the steady state for
// u ≡ 0.5.
core::Problem DacPlant(int K);

// 0.8967·0.5 + 0.3 sin(2π f t), t = 3 ms · step. f = 2 Hz lies in the filter's passband.
double DacTarget(int step, double frequency_hz = 2.0);

// The plant with binary inputs ({0, 1}, EM or AM) and y[n] ~ N(target(first + n), V_Y).
core::Problem DacWindow(int K, double output_variance, int first_step, double frequency_hz, bool em = true);

struct DacPlan {
  Eigen::VectorXd inputs;   ///< K binary inputs
  Eigen::VectorXd outputs;  ///< y[0..K] of the rounded plan
  Eigen::VectorXd target;   ///< target[0..K]
  double mse = 0.0;         ///< over steps 1..K-2 (the last two inputs affect nothing)
  int iterations = 0;
  double discrete_gap = 0.0;  ///< before rounding
  double seconds = 0.0;
};

// One long plan over K steps with an iteration budget (EM binarises slowly: §7.2).
absl::StatusOr<DacPlan> DacLongPlan(int K, double output_variance, double frequency_hz, int iterations, bool em);

struct DacOnlineRun {
  Eigen::VectorXd nup_inputs, exhaustive_inputs;    ///< applied inputs, one per step
  Eigen::VectorXd nup_outputs, exhaustive_outputs;  ///< y[1..steps] of each closed loop
  Eigen::VectorXd target;                           ///< target[1..steps]
  double nup_mse = 0.0, exhaustive_mse = 0.0;
  double largest_gap = 0.0;  ///< largest pre-rounding distance to {0, 1} over all windows
  double nup_seconds = 0.0;  ///< total time of the NUP solves
};

// Receding horizon ([KL] Fig. 19): at every step a window of `window` steps is planned
// from the measured state, by IAKE-EM (`iterations` per window, cold, rounded) and by
// exhaustive search over all 2^window binary sequences; each loop applies its own first
// input. The window's cost is Σ (y[n] - target)² over n = 1..window.
absl::StatusOr<DacOnlineRun> DacOnline(int window, int steps, double output_variance, double frequency_hz,
                                       int iterations);

struct DacExhaustiveRun {
  Eigen::VectorXd inputs;   ///< applied inputs, one per step
  Eigen::VectorXd outputs;  ///< y[1..steps]
  Eigen::VectorXd target;   ///< target[1..steps]
  double mse = 0.0;
};

// The exhaustive-search receding-horizon loop alone over `steps` steps with a `window`-step
// horizon, from x[0] of DacPlant (Fig. 19's reference, and Fig. 18's short-horizon side).
DacExhaustiveRun RunDacExhaustive(int window, int steps, double frequency_hz);

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_SCENARIOS_DAC_H_
