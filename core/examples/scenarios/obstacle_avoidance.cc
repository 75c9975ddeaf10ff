#include "core/examples/scenarios/obstacle_avoidance.h"

#include <algorithm>
#include <numbers>

#include "core/public/session.h"
#include "core/public/status_macros.h"

namespace nupmpc::examples {

using core::KeepOutRegion;

core::Problem ObstaclePlant(int horizon, double T) {
  core::Problem p = core::Problem::TimeInvariant(4, 2, 2, horizon);
  p.A[0] << 1, 0, 0, 0,  //
      T, 1, 0, 0,        //
      0, 0, 1, 0,        //
      0, 0, T, 1;
  p.B[0] << T, 0, 0, 0, 0, T, 0, 0;
  p.C[0] << 0, 1, 0, 0, 0, 0, 0, 1;
  p.initial_mean = Eigen::Vector4d::Zero();
  for (core::ScalarPrior& prior : p.input_priors) prior = core::ScalarPrior::Gaussian(0.0, 0.1);
  p.terminal = core::Problem::Terminal{Eigen::Vector4d(0.0, 3.0, 0.0, 3.0), 1e8 * Eigen::Matrix4d::Identity()};
  return p;
}

std::vector<KeepOutRegion> SingleCircleScene(double slope) { return {KeepOutRegion::Circle({1.5, 1.5}, 0.75, slope)}; }

std::vector<KeepOutRegion> MixedShapesScene(double slope) {
  constexpr double kPi = std::numbers::pi;
  return {
      KeepOutRegion::Circle({0.9, 0.6}, 0.35, slope),
      KeepOutRegion::Ellipse({1.6, 1.7}, 0.6, 0.25, kPi / 4, slope),
      KeepOutRegion::Rectangle({2.4, 1.0}, 0.3, 0.2, kPi / 6, slope),
      KeepOutRegion::Rectangle({1.0, 2.3}, 0.25, 0.4, 0.0, slope),
  };
}

absl::StatusOr<ObstacleRun> PlanAroundObstacles(int horizon, const std::vector<KeepOutRegion>& regions,
                                                core::SequentialOptions options) {
  const core::Problem plant = ObstaclePlant(horizon);
  // The obstacle-free optimum (a straight line) is the first linearisation point.
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<core::Session> free_flight, core::Session::Create(plant));
  core::Solution guess;
  NUPMPC_RETURN_IF_ERROR(free_flight->Solve(&guess).status());

  core::KeepOut keep_out;
  keep_out.regions = regions;
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<core::Linearisation> linearisation,
                          core::MakeKeepOutLinearisation(plant, keep_out));
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<core::SequentialSolver> solver,
                          core::SequentialSolver::Create(std::move(linearisation), {}, options));
  ObstacleRun run;
  NUPMPC_ASSIGN_OR_RETURN(run.summary, solver->Solve(guess, &run.plan));
  run.positions = core::PlantOutputs(run.plan, 2);
  run.min_clearance = core::kInfinity;
  for (int n = 1; n <= horizon; ++n) {
    for (const KeepOutRegion& region : regions) {
      run.min_clearance = std::min(run.min_clearance, core::KeepOutClearance(region, run.positions.row(n)));
    }
  }
  run.goal_error =
      (run.plan.states.row(horizon).transpose() - Eigen::Vector4d(0.0, 3.0, 0.0, 3.0)).cwiseAbs().maxCoeff();
  return run;
}

}  // namespace nupmpc::examples
