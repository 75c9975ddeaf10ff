#include "client/examples/bicycle.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace nupmpc::api_examples {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
constexpr int kStates = 4, kInputs = 2, kOutputs = 4;

double PathSlope(const BicycleScenario& s, double x) {
  const double k = 2 * std::numbers::pi / s.path_wavelength;
  return s.path_amplitude * k * std::cos(k * x);
}

double NearestClearance(const std::vector<Obstacle>& obstacles, double x, double y) {
  double nearest = kInfinity;
  for (const Obstacle& o : obstacles) nearest = std::min(nearest, Clearance(o, x, y));
  return nearest;
}

v1::KeepOutRegion Region(const Obstacle& o, double margin) {
  v1::KeepOutRegion r;
  r.set_shape(o.shape == Obstacle::Shape::kCircle ? v1::KeepOutRegion::SHAPE_ELLIPSE
                                                  : v1::KeepOutRegion::SHAPE_RECTANGLE);
  r.set_centre_x(o.centre_x);
  r.set_centre_y(o.centre_y);
  r.set_half_axis_a(o.half_a);
  r.set_half_axis_b(o.shape == Obstacle::Shape::kCircle ? o.half_a : o.half_b);
  r.set_rotation_rad(o.rotation);
  // The plant moves under the true nonlinear model, the plan under its linearisation: the
  // margin keeps what second-order error there is away from the obstacle itself.
  r.set_margin(margin);
  return r;
}

}  // namespace

double Clearance(const Obstacle& o, double x, double y) {
  const double dx = x - o.centre_x, dy = y - o.centre_y;
  if (o.shape == Obstacle::Shape::kCircle) return std::hypot(dx, dy) - o.half_a;
  // In the rectangle's own frame: the distance to the box outside, minus the distance to
  // the nearest side inside.
  const double c = std::cos(o.rotation), s = std::sin(o.rotation);
  const double qx = std::abs(c * dx + s * dy) - o.half_a, qy = std::abs(-s * dx + c * dy) - o.half_b;
  return std::hypot(std::max(qx, 0.0), std::max(qy, 0.0)) + std::min(std::max(qx, qy), 0.0);
}

std::vector<Obstacle> DefaultObstacles(double amplitude, double wavelength) {
  const auto path = [&](double x) { return amplitude * std::sin(2 * std::numbers::pi * x / wavelength); };
  Obstacle first{.shape = Obstacle::Shape::kCircle, .centre_x = 18.0, .centre_y = path(18.0) + 0.2, .half_a = 1.0};
  Obstacle second{.shape = Obstacle::Shape::kRectangle,
                  .centre_x = 36.0,
                  .centre_y = path(36.0) + 0.8,
                  .half_a = 1.5,
                  .half_b = 0.6,
                  .rotation = 0.4};
  Obstacle third{.shape = Obstacle::Shape::kCircle, .centre_x = 55.0, .centre_y = path(55.0) - 0.4, .half_a = 1.2};
  return {first, second, third};
}

double PathY(const BicycleScenario& s, double x) {
  return s.path_amplitude * std::sin(2 * std::numbers::pi * x / s.path_wavelength);
}

NonlinearModel BicycleModel(const BicycleScenario& scenario, bool analytic_jacobians) {
  const double dt = scenario.dt, ell = scenario.wheelbase;
  NonlinearModel model;
  model.num_states = kStates;
  model.num_inputs = kInputs;
  model.num_outputs = kOutputs;
  model.transition = [dt, ell](std::int64_t, const std::vector<double>& x, const std::vector<double>& u) {
    const double psi = x[2], v = x[3];
    return std::vector<double>{x[0] + dt * v * std::cos(psi), x[1] + dt * v * std::sin(psi),
                               psi + dt * v * std::tan(u[1]) / ell, v + dt * u[0]};
  };
  model.output = [scenario](std::int64_t, const std::vector<double>& x) {
    return std::vector<double>{x[0], x[1], x[1] - PathY(scenario, x[0]), x[3]};
  };
  if (!analytic_jacobians) return model;
  model.transition_x = [dt, ell](std::int64_t, const std::vector<double>& x, const std::vector<double>& u) {
    const double psi = x[2], v = x[3], c = std::cos(psi), s = std::sin(psi);
    return std::vector<double>{1, 0, -dt * v * s, dt * c,  //
                               0, 1, dt * v * c,  dt * s,  //
                               0, 0, 1,           dt * std::tan(u[1]) / ell,
                               0, 0, 0,           1};
  };
  model.transition_u = [dt, ell](std::int64_t, const std::vector<double>& x, const std::vector<double>& u) {
    const double t = std::tan(u[1]);
    return std::vector<double>{0,  0,  //
                               0,  0,  //
                               0,  dt * x[3] * (1 + t * t) / ell,
                               dt, 0};
  };
  model.output_x = [scenario](std::int64_t, const std::vector<double>& x) {
    return std::vector<double>{1,
                               0,
                               0,
                               0,  //
                               0,
                               1,
                               0,
                               0,  //
                               -PathSlope(scenario, x[0]),
                               1,
                               0,
                               0,
                               0,
                               0,
                               0,
                               1};
  };
  return model;
}

v1::ProblemSpec BicycleSpec(const BicycleScenario& s) {
  v1::ProblemSpec spec;
  const int N = s.horizon;
  spec.mutable_model()->set_horizon(N);
  for (const double x : s.start) spec.mutable_initial_state()->add_mean(x);
  // Inputs: hard boxes, with a small Gaussian part (effort); input boxes and output bounds
  // together then run on IFFBDD, which needs one.
  v1::ComponentPrior* acceleration = spec.add_input_priors();
  acceleration->set_kind(v1::PRIOR_KIND_BOX);
  acceleration->add_lower(s.min_acceleration);
  acceleration->add_upper(s.max_acceleration);
  acceleration->add_weight(s.acceleration_weight);
  v1::ComponentPrior* steering = spec.add_input_priors();
  steering->set_kind(v1::PRIOR_KIND_BOX);
  steering->add_lower(-s.max_steering);
  steering->add_upper(s.max_steering);
  steering->add_weight(s.steering_weight);
  spec.add_output_priors();  // px: free (the obstacles' plane)
  spec.add_output_priors();  // py: free
  v1::ComponentPrior* lateral = spec.add_output_priors();
  lateral->add_weight(s.lateral_weight);  // e → 0
  lateral->add_target(0.0);
  v1::ComponentPrior* speed = spec.add_output_priors();
  speed->set_kind(v1::PRIOR_KIND_AT_MOST);
  for (int n = 0; n <= N; ++n) speed->add_upper(n == 0 ? kInfinity : s.speed_limit);  // x[0] is measured
  speed->add_weight(s.speed_weight);
  speed->add_target(s.speed_reference);
  v1::KeepOut* keep_out = spec.mutable_keep_out();
  keep_out->set_first_output(0);
  keep_out->set_second_output(1);
  for (const Obstacle& o : s.obstacles) *keep_out->add_regions() = Region(o, s.margin);
  return spec;
}

absl::StatusOr<BicycleRun> RunBicycle(Client& client, const BicycleScenario& scenario,
                                      const NonlinearSessionOptions& options, bool analytic_jacobians,
                                      const std::function<void(const BicyclePeriod&)>& on_period) {
  const NonlinearModel model = BicycleModel(scenario, analytic_jacobians);
  absl::StatusOr<std::unique_ptr<NonlinearSession>> session =
      NonlinearSession::Create(client, model, BicycleSpec(scenario), options);
  if (!session.ok()) return session.status();
  BicycleRun run;
  std::vector<double> x = scenario.start;
  for (int period = 0; period < scenario.max_periods && !run.reached_goal; ++period) {
    absl::StatusOr<NonlinearPlan> plan = (*session)->Step(x);
    if (!plan.ok()) return plan.status();
    if (!plan->has_plan) {
      return absl::InternalError(
          absl::StrCat("period ", period, ": no plan (status ", v1::SolveStatus_Name(plan->result.status()), ")"));
    }
    BicyclePeriod p;
    p.period = period;
    p.state = x;
    p.input = {plan->inputs[0], plan->inputs[1]};
    p.lateral_error = x[1] - PathY(scenario, x[0]);
    p.clearance = NearestClearance(scenario.obstacles, x[0], x[1]);
    p.plan_clearance = kInfinity;
    for (int n = 1; n <= scenario.horizon; ++n) {
      p.plan_clearance = std::min(p.plan_clearance, NearestClearance(scenario.obstacles, plan->states[n * kStates],
                                                                     plan->states[n * kStates + 1]));
    }
    p.status = plan->result.status();
    p.max_violation = plan->result.max_violation();
    p.report = plan->report;
    x = model.transition(period, x, p.input);  // the car: the nonlinear model itself
    run.reached_goal = x[0] >= scenario.goal_x;
    if (on_period) on_period(p);
    run.periods.push_back(std::move(p));
  }
  run.final_state = x;
  (void)(*session)->Close();
  return run;
}

}  // namespace nupmpc::api_examples
