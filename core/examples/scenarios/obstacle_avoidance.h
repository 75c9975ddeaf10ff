#ifndef NUPMPC_CORE_EXAMPLES_SCENARIOS_OBSTACLE_AVOIDANCE_H_
#define NUPMPC_CORE_EXAMPLES_SCENARIOS_OBSTACLE_AVOIDANCE_H_

// Trajectory planning with obstacle avoidance ([KL] §V-D): a point mass in the plane,
// model (93) (state [v1, p1, v2, p2], acceleration input), cost Σ‖u‖² as a zero-mean
// Gaussian prior with variance 0.1 per component, from (0,0) at rest to (3,3) at rest,
// around keep-out regions (core/nonlinear/keep_out.h).

#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/nupmpc.h"
#include "core/public/nonlinear.h"

namespace nupmpc::examples {

// Model (93) with T, horizon N, x[0] = 0 and the goal (3,3) at rest as a terminal cost
// (weight 1e8: the paper's V_XK = 0 as a penalty the message passing can carry).
core::Problem ObstaclePlant(int horizon, double T = 1.0);

// The paper's single obstacle: circle at (1.5, 1.5), radius 0.75, half-space slope γ.
std::vector<core::KeepOutRegion> SingleCircleScene(double slope);
// Several shapes between start and goal (circle, rotated ellipse, rotated rectangle,
// rectangle) like Fig. 23b.
std::vector<core::KeepOutRegion> MixedShapesScene(double slope);

struct ObstacleRun {
  core::Solution plan;  ///< of the linearised problem (plant outputs first)
  core::SequentialSummary summary;
  Eigen::MatrixXd positions;   ///< (N+1) × 2
  double min_clearance = 0.0;  ///< smallest KeepOutClearance over steps 1..N and regions
  double goal_error = 0.0;     ///< ‖x[N] - (0,3,0,3)‖∞
};

// Plans around `regions`, starting from the obstacle-free plan (the straight line).
absl::StatusOr<ObstacleRun> PlanAroundObstacles(int horizon, const std::vector<core::KeepOutRegion>& regions,
                                                core::SequentialOptions options = {});

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_SCENARIOS_OBSTACLE_AVOIDANCE_H_
