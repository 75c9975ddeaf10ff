#ifndef NUPMPC_CORE_EXAMPLES_SCENARIOS_FLAPPY_BIRD_H_
#define NUPMPC_CORE_EXAMPLES_SCENARIOS_FLAPPY_BIRD_H_

// Flappy bird control ([KL] §V-C, eqs. 90–92): a point mass moves right at constant speed
// and falls with acceleration g; a binary flap u ∈ {0, 1} adds 1/m to its vertical
// velocity. It must pass walls with two slits each: at a wall step, y ∈ [a, b] (upper
// slit) or y ∈ [a - d, b - d] (lower slit).
//
// [KL] writes ỹ = y + s with a binary s ∈ {0, d} and a box on ỹ. Our model has no direct
// input-to-output term, so s is carried by a third state: x = [y, v, s], s[n+1] = w[n]
// with a second, binary input w[n] ∈ {0, d} on the step before a wall; across the wall s
// is held, so one selector picks the slit for the whole wall. The box on ỹ = y + s has
// the paper's slope γ = 100; y also stays in [0, 10] (same slope).

#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"

namespace nupmpc::examples {

struct FlappyParameters {
  double mass = 1.0;
  double period = 0.1;   ///< T
  double gravity = 0.2;  ///< g
  double slope = 100.0;  ///< γ of the slit boxes
  double start_height = 5.0;
};

struct Wall {
  int first_step = 0;  ///< wall occupies steps first_step .. first_step + width - 1
  int width = 1;
  double upper_low = 0.0, upper_high = 0.0;  ///< the upper slit [a, b]
  double separation = 0.0;                   ///< d: the lower slit is [a - d, b - d]
};

// `count` walls spread over `steps` steps with slit positions drawn from `seed`.
std::vector<Wall> RandomWalls(int steps, int count, unsigned seed);

struct FlappyRun {
  Eigen::VectorXd flaps;              ///< u[0..K-1] ∈ {0, 1}
  Eigen::VectorXd height;             ///< y[0..K], simulated from the flaps
  double worst_slit_violation = 0.0;  ///< largest distance of y outside both slits, over wall steps
  int iterations = 0;
  double discrete_gap = 0.0;
  int discrete_moves = 0;  ///< level changes of the discrete local search after rounding
  double seconds = 0.0;
};

// Largest distance of height[n] outside both slits of the wall at n, over all wall steps.
double WorstSlitViolation(const std::vector<Wall>& walls, const Eigen::VectorXd& height);

absl::StatusOr<FlappyRun> FlyThroughWalls(int steps, const std::vector<Wall>& walls, const FlappyParameters& params,
                                          int iterations = 2000);

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_SCENARIOS_FLAPPY_BIRD_H_
