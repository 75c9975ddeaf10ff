#ifndef NUPMPC_CORE_EXAMPLES_SCENARIOS_CORRIDOR_H_
#define NUPMPC_CORE_EXAMPLES_SCENARIOS_CORRIDOR_H_

// Corridor control with different input constraints ([KL] §V-B, model (89), K = 175):
// the output of a triple integrator must stay in a corridor around a target (a hard box
// on y), while the input is shaped five ways:
//   1. L2:           u ~ N(0, 10)
//   2. Δu ≥ -0.03:   a hard half-space on the input differences
//   3. sparse u:     plain NUV (EM) on u
//   4. u ∈ {-1,0,1}: an M-level input (two binaries, EM)
//   5. sparse Δu:    plain NUV (EM) on the input differences
// The paper shows the corridor only as a figure: ours rises to 4, holds, drops to 1.6
// and holds (half-width 0.2). Version 4 uses the paper's soft corridor (slope 10), the
// others a hard one.

#include <string>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/nupmpc.h"

namespace nupmpc::examples {

enum class CorridorVersion { kL2 = 1, kRateLimit = 2, kSparseInput = 3, kThreeLevels = 4, kSparseChanges = 5 };
const char* CorridorVersionName(CorridorVersion version);

inline constexpr int kCorridorSteps = 175;
inline constexpr double kCorridorHalfWidth = 0.2;

double CorridorTarget(int step);

struct CorridorRun {
  Eigen::VectorXd inputs;               ///< u[0..K-1]
  Eigen::VectorXd outputs;              ///< y[0..K] (simulated from the inputs)
  double max_corridor_violation = 0.0;  ///< largest distance of y[1..K] outside the corridor
  int nonzero_inputs = 0;               ///< |u| > 1e-6
  int input_switches = 0;               ///< |Δu| > 1e-6 (with u[-1] = 0)
  double min_input_change = 0.0;        ///< smallest Δu
  double level_gap = 0.0;               ///< largest distance of u to {-1, 0, 1}
  double discrete_gap = 0.0;            ///< binaries before rounding (version 4)
  int iterations = 0;
  double seconds = 0.0;
};

// The NUP problem of a version: model (89) (augmented for Δu, expanded for three levels)
// with the corridor on output 0.
absl::StatusOr<core::Problem> CorridorProblem(CorridorVersion version);

absl::StatusOr<CorridorRun> RunCorridor(CorridorVersion version, int iterations = 3000);

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_SCENARIOS_CORRIDOR_H_
