#include "client/examples/race_track.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace nupmpc::api_examples {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
constexpr int kStates = 6, kInputs = 2, kOutputs = 4;
// The bounds of [KL] §V-E on z (the track's half width), a, δ and a_tot², and the scale of
// each output (the largest magnitude of its bounds): scaled outputs have bounds of size 1,
// so the step control compares their linearisation errors on one scale.
constexpr double kLower[kOutputs] = {-0.006, -1.0, -0.35, 0.0};
constexpr double kUpper[kOutputs] = {0.006, 1.0, 0.35, 150.0};
constexpr double kOutputScale[kOutputs] = {0.006, 1.0, 0.35, 150.0};

}  // namespace

double Track::length() const {
  double total = 0.0;
  for (const Piece& piece : pieces) total += piece.length;
  return total;
}

double Track::curvature_at(double s) const {
  s = std::fmod(s, length());
  if (s < 0) s += length();
  for (const Piece& piece : pieces) {
    if (s < piece.length) return piece.curvature;
    s -= piece.length;
  }
  return pieces.back().curvature;
}

Track DemoTrack() {
  constexpr double kW = 1.2, kH = 0.7, kHalfPi = std::numbers::pi / 2;
  const double r_br = 0.06, r_tr = 0.15, r_tl = 0.06, r_bl = 0.10;
  const double chicane_r = 0.08, chicane_angle = 0.6;
  const double chicane_extent = 4 * chicane_r * std::sin(chicane_angle);
  const double front = kW - r_bl - r_br, back = kW - r_tr - r_tl;
  const double back_straight = (back - chicane_extent) / 2;
  Track t;
  t.pieces = {
      {front / 2, 0.0},
      {kHalfPi * r_br, 1 / r_br},
      {kH - r_br - r_tr, 0.0},
      {kHalfPi * r_tr, 1 / r_tr},
      {back_straight, 0.0},
      {chicane_angle * chicane_r, 1 / chicane_r},
      {2 * chicane_angle * chicane_r, -1 / chicane_r},
      {chicane_angle * chicane_r, 1 / chicane_r},
      {back_straight, 0.0},
      {kHalfPi * r_tl, 1 / r_tl},
      {kH - r_tl - r_bl, 0.0},
      {kHalfPi * r_bl, 1 / r_bl},
      {front / 2, 0.0},
  };
  return t;
}

NonlinearModel RaceModel(const Track& track, const Vehicle& vehicle, int steps) {
  const double ds = track.length() / steps, ell = vehicle.length, lateral = vehicle.psi / (ell * ell);
  std::vector<double> kappa(steps + 1);
  for (int n = 0; n <= steps; ++n) kappa[n] = track.curvature_at(n * ds);
  // The curvature under spatial step t (clamped: the shifted plan's extra step looks one
  // past the lap's end).
  const auto curvature = [kappa](std::int64_t t) {
    return kappa[static_cast<std::size_t>(std::clamp<std::int64_t>(t, 0, static_cast<std::int64_t>(kappa.size()) - 1))];
  };
  NonlinearModel model;
  model.num_states = kStates;
  model.num_inputs = kInputs;
  model.num_outputs = kOutputs;
  // x[n+1] = x[n] + ds f_s(x[n], u[n]) with, for e = 1 − κz and g = e / (v cos θ) = dt/ds:
  // z' = e tan θ, θ' = e tan δ / (ℓ cos θ) − κ, v' = g a, a' = g u1, δ' = g u0, t' = g.
  model.transition = [curvature, ds, ell](std::int64_t t, const std::vector<double>& x, const std::vector<double>& u) {
    const double k = curvature(t), z = x[0], th = x[1], v = x[2], a = x[3], d = x[4];
    const double e = 1 - k * z, c = std::cos(th), s = std::sin(th), td = std::tan(d), g = e / (v * c);
    const double rate[kStates] = {e * s / c, e * td / (ell * c) - k, g * a, g * u[1], g * u[0], g};
    std::vector<double> next(kStates);
    for (int i = 0; i < kStates; ++i) next[i] = x[i] + ds * rate[i];
    return next;
  };
  model.transition_x = [curvature, ds, ell](std::int64_t t, const std::vector<double>& x,
                                            const std::vector<double>& u) {
    const double k = curvature(t), z = x[0], th = x[1], v = x[2], a = x[3], d = x[4];
    const double e = 1 - k * z, c = std::cos(th), s = std::sin(th), td = std::tan(d), g = e / (v * c);
    const double dg[3] = {-k / (v * c), e * s / (v * c * c), -e / (v * v * c)};  // ∂g/∂(z, θ, v)
    std::vector<double> J(kStates * kStates, 0.0);
    const auto at = [&J](int i, int j) -> double& { return J[i * kStates + j]; };
    at(0, 0) = -k * s / c;
    at(0, 1) = e / (c * c);
    at(1, 0) = -k * td / (ell * c);
    at(1, 1) = e * td * s / (ell * c * c);
    at(1, 4) = e * (1 + td * td) / (ell * c);
    for (int j = 0; j < 3; ++j) {
      at(2, j) = a * dg[j];
      at(3, j) = u[1] * dg[j];
      at(4, j) = u[0] * dg[j];
      at(5, j) = dg[j];
    }
    at(2, 3) = g;
    for (double& entry : J) entry *= ds;
    for (int i = 0; i < kStates; ++i) at(i, i) += 1.0;
    return J;
  };
  model.transition_u = [curvature, ds](std::int64_t t, const std::vector<double>& x, const std::vector<double>&) {
    const double g = (1 - curvature(t) * x[0]) / (x[2] * std::cos(x[1]));
    std::vector<double> B(kStates * kInputs, 0.0);
    B[4 * kInputs + 0] = ds * g;
    B[3 * kInputs + 1] = ds * g;
    return B;
  };
  model.output = [lateral](std::int64_t, const std::vector<double>& x) {
    const double v = x[2], a = x[3], td = std::tan(x[4]);
    std::vector<double> y = {x[0], a, x[4], a * a + lateral * std::pow(v, 4) * td * td};
    for (int k = 0; k < kOutputs; ++k) y[k] /= kOutputScale[k];
    return y;
  };
  model.output_x = [lateral](std::int64_t, const std::vector<double>& x) {
    const double v = x[2], a = x[3], td = std::tan(x[4]);
    std::vector<double> C(kOutputs * kStates, 0.0);
    C[0 * kStates + 0] = 1;
    C[1 * kStates + 3] = 1;
    C[2 * kStates + 4] = 1;
    C[3 * kStates + 2] = 4 * lateral * std::pow(v, 3) * td * td;
    C[3 * kStates + 3] = 2 * a;
    C[3 * kStates + 4] = 2 * lateral * std::pow(v, 4) * td * (1 + td * td);
    for (int k = 0; k < kOutputs; ++k) {
      for (int j = 0; j < kStates; ++j) C[k * kStates + j] /= kOutputScale[k];
    }
    return C;
  };
  return model;
}

v1::ProblemSpec RaceSpec(int steps, double start_speed) {
  v1::ProblemSpec spec;
  spec.mutable_model()->set_horizon(steps);
  for (const double x : {0.0, 0.0, start_speed, 0.0, 0.0, 0.0}) spec.mutable_initial_state()->add_mean(x);
  for (int l = 0; l < kInputs; ++l) {
    v1::ComponentPrior* p = spec.add_input_priors();
    p->add_weight(1e-8);  // N(0, 1e8): the inputs are (nearly) free
    p->add_target(0.0);
  }
  for (int k = 0; k < kOutputs; ++k) {
    v1::ComponentPrior* p = spec.add_output_priors();
    p->set_kind(v1::PRIOR_KIND_BOX);
    for (int n = 0; n <= steps; ++n) {  // from step 1 on: x[0] is given
      p->add_lower(n == 0 ? -kInfinity : kLower[k] / kOutputScale[k]);
      p->add_upper(n == 0 ? kInfinity : kUpper[k] / kOutputScale[k]);
    }
  }
  // t[K] ~ N(0, 500): minimal lap time.
  v1::TerminalCost* terminal = spec.mutable_terminal();
  terminal->mutable_target()->Resize(kStates, 0.0);
  terminal->mutable_weight()->set_rows(kStates);
  terminal->mutable_weight()->set_cols(kStates);
  terminal->mutable_weight()->mutable_data()->Resize(kStates * kStates, 0.0);
  terminal->mutable_weight()->set_data(kStates * kStates - 1, 1.0 / 500.0);
  // The core example's tolerances (RaceSettings::DefaultSolverOptions): 1e-7 of a unit
  // bound is below what the Euler model resolves, and a linearised problem not solved in
  // 1000 passes was linearised with too wide a proximal term (the step control narrows it).
  spec.mutable_options()->set_violation_tolerance(1e-7);
  spec.mutable_options()->set_max_iterations(1000);
  return spec;
}

InitialGuess RaceGuess(const Track& track, const Vehicle& vehicle, int steps, double start_speed) {
  const double ds = track.length() / steps;
  InitialGuess guess;
  guess.inputs.assign(static_cast<std::size_t>(steps) * kInputs, 0.0);
  for (int n = 0; n <= steps; ++n) {
    const double state[kStates] = {
        0.0, 0.0, start_speed, 0.0, std::atan(vehicle.length * track.curvature_at(n * ds)), n * ds / start_speed};
    guess.states.insert(guess.states.end(), state, state + kStates);
  }
  return guess;
}

NonlinearSessionOptions RaceOptions(const RaceSettings& settings) {
  NonlinearSessionOptions options;
  options.max_linearisations = settings.max_linearisations;
  options.step_tolerance = 1e-6;
  options.region.state_radius.assign(kStates, kInfinity);
  // dt/ds = 1/v linearised says "drive infinitely fast": the speed may move only this much
  // per linearisation.
  options.region.state_radius[2] = settings.speed_trust_radius;
  options.region.state_proximal_stddev.assign(kStates, settings.proximal_stddev);
  options.region.input_proximal_stddev.assign(kInputs, settings.proximal_stddev);
  options.step_control.growth = 1.5;
  options.step_control.max_scale = 100.0;
  options.step_control.shrink = 4.0;
  return options;
}

absl::StatusOr<RaceLapRun> RunRaceLap(Client& client, const Track& track, const Vehicle& vehicle, int steps,
                                      const RaceSettings& settings) {
  const NonlinearModel model = RaceModel(track, vehicle, steps);
  absl::StatusOr<std::unique_ptr<NonlinearSession>> session =
      NonlinearSession::Create(client, model, RaceSpec(steps, settings.start_speed), RaceOptions(settings),
                               RaceGuess(track, vehicle, steps, settings.start_speed));
  if (!session.ok()) return session.status();
  const std::vector<double> start = {0.0, 0.0, settings.start_speed, 0.0, 0.0, 0.0};
  absl::StatusOr<NonlinearPlan> plan = (*session)->Step(start);
  if (!plan.ok()) return plan.status();
  if (!plan->has_plan) {
    return absl::InternalError(
        absl::StrCat("the lap has no plan: status ", v1::SolveStatus_Name(plan->result.status())));
  }
  RaceLapRun run;
  run.report = plan->report;
  run.states = plan->states;
  run.lap_time = plan->states[static_cast<std::size_t>(steps) * kStates + 5];
  // The bounds on the true outputs h(x) of the plan's states, in the bounds' own units.
  for (int n = 1; n <= steps; ++n) {
    const std::vector<double> x(plan->states.begin() + n * kStates, plan->states.begin() + (n + 1) * kStates);
    const std::vector<double> y = model.output(n, x);
    for (int k = 0; k < kOutputs; ++k) {
      const double value = kOutputScale[k] * y[k];
      run.max_output_violation = std::max({run.max_output_violation, kLower[k] - value, value - kUpper[k]});
    }
  }
  (void)(*session)->Close();
  return run;
}

}  // namespace nupmpc::api_examples
