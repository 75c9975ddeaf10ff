#ifndef NUPMPC_CLIENT_EXAMPLES_BICYCLE_H_
#define NUPMPC_CLIENT_EXAMPLES_BICYCLE_H_

// A kinematic bicycle following a curved path past obstacles, in closed loop through the
// v1 API with the real-time iteration (NonlinearSession): each period the client
// linearises the car along the previous plan shifted by one step, the server plans on that
// time-varying linear model with the obstacles as keep-out regions, and the car (the
// nonlinear model itself) moves under the plan's first input.
//
//   x = [px, py, heading ψ, speed v],  u = [acceleration a, steering δ],
//   px⁺ = px + Δt v cos ψ,  py⁺ = py + Δt v sin ψ,  ψ⁺ = ψ + Δt v tan δ / ℓ,  v⁺ = v + Δt a,
//   y = [px, py, e = py − path(px), v],  path(x) = A sin(2π x / λ).
//
// Hard bounds: |δ| ≤ max_steering, a ∈ [min_acceleration, max_acceleration], v ≤ speed_limit
// (the driver asks for more: the bound is active on the straights), and the obstacles
// (keep-out regions on (px, py), enlarged by `margin`). Soft goals: e → 0, v → speed_reference.

#include <functional>
#include <vector>

#include "absl/status/statusor.h"
#include "client/client.h"
#include "client/nonlinear_session.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::api_examples {

struct Obstacle {
  enum class Shape { kCircle, kRectangle };
  Shape shape = Shape::kCircle;
  double centre_x = 0.0, centre_y = 0.0;
  double half_a = 1.0;    // circle: the radius; rectangle: half its length along its own axis
  double half_b = 1.0;    // rectangle: half its width
  double rotation = 0.0;  // rectangle: of its own axis, radians counter-clockwise
};

// Signed distance from the point (x, y) to the obstacle: > 0 outside, < 0 inside.
double Clearance(const Obstacle& obstacle, double x, double y);

// A circle on the path, a tilted rectangle beside it and another circle on the other side.
std::vector<Obstacle> DefaultObstacles(double path_amplitude, double path_wavelength);

struct BicycleScenario {
  double dt = 0.1;                                         // s
  double wheelbase = 2.5;                                  // m
  int horizon = 30;                                        // 3 s of look-ahead
  double path_amplitude = 1.5;                             // m
  double path_wavelength = 50.0;                           // m
  double speed_reference = 5.5;                            // m/s, what the driver asks for
  double speed_limit = 5.0;                                // m/s, hard
  double max_steering = 0.6;                               // rad
  double min_acceleration = -3.0, max_acceleration = 2.0;  // m/s²
  double margin = 0.3;                                     // m kept from every obstacle beyond its size
  // Weights (½·w·(v − target)²) of the soft goals and of the inputs' effort.
  double lateral_weight = 1.0;
  double speed_weight = 1.0;
  double acceleration_weight = 0.5;
  double steering_weight = 1.0;
  std::vector<Obstacle> obstacles = DefaultObstacles(1.5, 50.0);
  double goal_x = 75.0;  // m: the run ends when px passes it
  int max_periods = 200;
  std::vector<double> start = {0.0, 0.0, 0.0, 3.0};  // px, py, ψ, v
};

double PathY(const BicycleScenario& scenario, double x);

// The car's model; `analytic_jacobians` false leaves them to finite differences.
NonlinearModel BicycleModel(const BicycleScenario& scenario, bool analytic_jacobians = true);

// Horizon, start, bounds, goals and obstacles as a spec for NonlinearSession::Create.
v1::ProblemSpec BicycleSpec(const BicycleScenario& scenario);

struct BicyclePeriod {
  int period = 0;
  std::vector<double> state;    // x[0], measured
  std::vector<double> input;    // u[0], applied
  double lateral_error = 0.0;   // e of x[0]
  double clearance = 0.0;       // of x[0]'s position to the nearest obstacle (its true shape)
  double plan_clearance = 0.0;  // the least over the plan's positions at steps 1..N
  v1::SolveStatus status = v1::SOLVE_STATUS_UNSPECIFIED;
  double max_violation = 0.0;  // of the plan's hard bounds (SolveResult.max_violation)
  PeriodReport report;
};

struct BicycleRun {
  std::vector<BicyclePeriod> periods;
  std::vector<double> final_state;  // after the last applied input
  bool reached_goal = false;
};

// The closed loop from scenario.start until px ≥ goal_x or max_periods. Fails when a
// period has no plan (the example has no fallback controller) or the server refuses.
// `on_period` sees each period as it is done (for printing).
absl::StatusOr<BicycleRun> RunBicycle(Client& client, const BicycleScenario& scenario,
                                      const NonlinearSessionOptions& options, bool analytic_jacobians = true,
                                      const std::function<void(const BicyclePeriod&)>& on_period = {});

}  // namespace nupmpc::api_examples

#endif  // NUPMPC_CLIENT_EXAMPLES_BICYCLE_H_
