#include "core/examples/scenarios/race_track.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/nupmpc.h"
#include "core/public/session.h"
#include "core/public/status_macros.h"

namespace nupmpc::examples {
namespace {

// Output bounds of [KL] §V-E (z, a, δ, a_tot²).
constexpr double kLower[4] = {-kTrackHalfWidth, -1.0, -0.35, 0.0};
constexpr double kUpper[4] = {kTrackHalfWidth, 1.0, 0.35, 150.0};
// The model's outputs are these quantities divided by the largest magnitude of their
// bounds, so that every bound is of size 1 and the sequential solver's step control
// compares the linearisation errors of z (bound 0.006) and a_tot² (bound 150) on one
// scale.
constexpr double kOutputScale[4] = {kTrackHalfWidth, 1.0, 0.35, 150.0};

// One straight or arc: the point and heading after `length` from (p, φ).
void Advance(double length, double curvature, Eigen::Vector2d* p, double* heading) {
  if (curvature == 0.0) {
    *p += length * Eigen::Vector2d(std::cos(*heading), std::sin(*heading));
    return;
  }
  const double r = 1.0 / curvature, end = *heading + length * curvature;
  *p += r * Eigen::Vector2d(std::sin(end) - std::sin(*heading), std::cos(*heading) - std::cos(end));
  *heading = end;
}

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

Eigen::Vector2d Track::point(double s, double z) const {
  s = std::fmod(s, length());
  if (s < 0) s += length();
  Eigen::Vector2d p = Eigen::Vector2d::Zero();
  double heading = 0.0;
  for (const Piece& piece : pieces) {
    const double step = std::min(s, piece.length);
    Advance(step, piece.curvature, &p, &heading);
    s -= step;
    if (s <= 0.0) break;
  }
  return p + z * Eigen::Vector2d(-std::sin(heading), std::cos(heading));
}

Track DemoTrack() {
  // A rounded rectangle (counter-clockwise, 1.2 × 0.7) with corners of different radii and
  // an S-chicane (+θ, -2θ, +θ: no net offset) on the back straight; the start line is in
  // the middle of the front straight.
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

core::NonlinearModel RaceModel(const Track& track, const Vehicle& vehicle, int steps) {
  const double ds = track.length() / steps, ell = vehicle.length, psi = vehicle.psi;
  std::vector<double> kappa(steps + 1);
  for (int n = 0; n <= steps; ++n) kappa[n] = track.curvature_at(n * ds);
  core::NonlinearModel model;
  model.num_states = 6;
  model.num_inputs = 2;
  model.num_outputs = 4;
  // x[n+1] = x[n] + ds f_s(x[n], u[n]) (eqs. 109, 113) with, for e = 1 - κz and
  // g = e / (v cos θ) = dt/ds:  z' = e tan θ,  θ' = e tan δ / (ℓ cos θ) - κ,
  // v' = g a,  a' = g u1,  δ' = g u0,  t' = g.
  model.transition = [kappa, ds, ell](int n, const Eigen::VectorXd& x, const Eigen::VectorXd& u, Eigen::VectorXd* next,
                                      Eigen::MatrixXd* A, Eigen::MatrixXd* B) {
    const double k = kappa[n], z = x(0), th = x(1), v = x(2), a = x(3), d = x(4);
    const double e = 1 - k * z, c = std::cos(th), s = std::sin(th), td = std::tan(d);
    const double g = e / (v * c);
    *next << e * s / c, e * td / (ell * c) - k, g * a, g * u(1), g * u(0), g;  // f_s
    *next = x + ds * *next;
    // ∂g/∂(z, θ, v)
    const Eigen::RowVector3d dg(-k / (v * c), e * s / (v * c * c), -e / (v * v * c));
    Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Zero();
    J(0, 0) = -k * s / c;
    J(0, 1) = e / (c * c);
    J(1, 0) = -k * td / (ell * c);
    J(1, 1) = e * td * s / (ell * c * c);
    J(1, 4) = e * (1 + td * td) / (ell * c);
    J.block<1, 3>(2, 0) = a * dg;
    J(2, 3) = g;
    J.block<1, 3>(3, 0) = u(1) * dg;
    J.block<1, 3>(4, 0) = u(0) * dg;
    J.block<1, 3>(5, 0) = dg;
    *A = Eigen::MatrixXd::Identity(6, 6) + ds * J;
    B->setZero();
    (*B)(4, 0) = ds * g;
    (*B)(3, 1) = ds * g;
  };
  // y = [z, a, δ, a² + ψ v⁴ tan²δ / ℓ²] (eq. 110), each divided by kOutputScale.
  model.output = [ell, psi](int, const Eigen::VectorXd& x, Eigen::VectorXd* y, Eigen::MatrixXd* C) {
    const double v = x(2), a = x(3), td = std::tan(x(4)), lateral = psi / (ell * ell);
    *y << x(0), a, x(4), a * a + lateral * std::pow(v, 4) * td * td;
    C->setZero();
    (*C)(0, 0) = 1;
    (*C)(1, 3) = 1;
    (*C)(2, 4) = 1;
    (*C)(3, 2) = 4 * lateral * std::pow(v, 3) * td * td;
    (*C)(3, 3) = 2 * a;
    (*C)(3, 4) = 2 * lateral * std::pow(v, 4) * td * (1 + td * td);
    for (int k = 0; k < 4; ++k) {
      (*y)(k) /= kOutputScale[k];
      C->row(k) /= kOutputScale[k];
    }
  };
  return model;
}

core::SequentialOptions RaceSettings::DefaultSequentialOptions() {
  core::SequentialOptions options;
  options.max_linearisations = 300;
  options.proximal_growth = 1.5;
  options.proximal_max_scale = 100.0;
  options.proximal_shrink = 4.0;
  return options;
}

core::SolverOptions RaceSettings::DefaultSolverOptions() {
  core::SolverOptions options;
  // The outputs are scaled to unit bounds; 1e-7 of a bound (6e-10 of the track's half
  // width) is below anything the Euler model resolves, and IFFBDD spends many passes on
  // the last decades of a near-degenerate problem.
  options.violation_tolerance = 1e-7;
  // A linearised problem IFFBDD has not solved in 1000 passes was linearised with too wide
  // a proximal term (the step control shrinks it): waiting longer rarely pays.
  options.max_iterations = 1000;
  return options;
}

double TotalAccelerationSquared(const Eigen::VectorXd& outputs) { return kOutputScale[3] * outputs(3); }

absl::StatusOr<RaceRun> RaceLap(const Track& track, const Vehicle& vehicle, int steps, const RaceSettings& settings) {
  const double v0 = settings.start_speed;
  core::NonlinearModel model = RaceModel(track, vehicle, steps);
  core::Problem problem = core::Problem::TimeInvariant(6, 2, 4, steps);
  problem.initial_mean = (Eigen::VectorXd(6) << 0, 0, v0, 0, 0, 0).finished();
  for (core::ScalarPrior& prior : problem.input_priors) prior = core::ScalarPrior::Gaussian(0.0, 1e8);
  for (int n = 1; n <= steps; ++n) {
    for (int k = 0; k < 4; ++k) {
      problem.mutable_output_prior(n, k) =
          core::ScalarPrior::Box(kLower[k] / kOutputScale[k], kUpper[k] / kOutputScale[k]);
    }
  }
  Eigen::MatrixXd time_weight = Eigen::MatrixXd::Zero(6, 6);
  time_weight(5, 5) = 1.0 / 500.0;  // t[K] ~ N(0, 500): minimal lap time
  problem.terminal = core::Problem::Terminal{Eigen::VectorXd::Zero(6), time_weight};

  // First point: drive the centre line at v0, steering along the curvature.
  const double ds = track.length() / steps;
  core::Solution guess;
  guess.inputs = Eigen::MatrixXd::Zero(steps, 2);
  guess.states = Eigen::MatrixXd::Zero(steps + 1, 6);
  for (int n = 0; n <= steps; ++n) {
    guess.states(n, 2) = v0;
    guess.states(n, 4) = std::atan(vehicle.length * track.curvature_at(n * ds));
    guess.states(n, 5) = n * ds / v0;
  }
  core::TrustRegion trust;
  trust.state_radius = Eigen::VectorXd::Constant(6, core::kInfinity);
  trust.state_radius(2) = settings.speed_trust_radius;
  trust.state_proximal_stddev = Eigen::VectorXd::Constant(6, settings.proximal_stddev);
  trust.input_proximal_stddev = Eigen::VectorXd::Constant(2, settings.proximal_stddev);
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<core::Linearisation> linearisation,
                          core::MakeModelLinearisation(model, problem, trust));
  NUPMPC_ASSIGN_OR_RETURN(
      std::unique_ptr<core::SequentialSolver> solver,
      core::SequentialSolver::Create(std::move(linearisation), settings.solver, settings.sequential));
  RaceRun run;
  NUPMPC_ASSIGN_OR_RETURN(run.summary, solver->Solve(guess, &run.plan));
  run.lap_time = run.plan.states(steps, 5);
  run.model_defect = run.summary.nonlinear_violation;
  // Bounds checked on the true outputs h(x) of the plan's states.
  Eigen::VectorXd y(4);
  Eigen::MatrixXd C(4, 6);
  for (int n = 1; n <= steps; ++n) {
    model.output(n, run.plan.states.row(n).transpose(), &y, &C);
    for (int k = 0; k < 4; ++k) {
      const double value = kOutputScale[k] * y(k);
      run.max_output_violation = std::max({run.max_output_violation, kLower[k] - value, value - kUpper[k]});
    }
  }
  return run;
}

double CentreLineLapTime(const Track& track, const Vehicle& vehicle, double start_speed, int samples) {
  const double ds = track.length() / samples, max_a = kUpper[1], max_total = kUpper[3];
  const auto lateral = [&](double v, double kappa) { return vehicle.psi * std::pow(v * v * kappa, 2); };
  // The speed the total-acceleration bound allows with no longitudinal acceleration, and
  // the longitudinal acceleration left at speed v.
  const auto top_speed = [&](double kappa) {
    return kappa == 0.0 ? core::kInfinity : std::pow(max_total / vehicle.psi, 0.25) / std::sqrt(std::abs(kappa));
  };
  const auto acceleration = [&](double v, double kappa) {
    return std::min(max_a, std::sqrt(std::max(0.0, max_total - lateral(v, kappa))));
  };
  std::vector<double> v(samples + 1), kappa(samples + 1);
  for (int n = 0; n <= samples; ++n) kappa[n] = track.curvature_at(n * ds);
  v[0] = start_speed;
  for (int n = 0; n < samples; ++n) {  // accelerate as hard as allowed ...
    v[n + 1] = std::min(top_speed(kappa[n + 1]), std::sqrt(v[n] * v[n] + 2 * acceleration(v[n], kappa[n]) * ds));
  }
  for (int n = samples - 1; n >= 1; --n) {  // ... and brake in time for every corner
    v[n] = std::min(v[n], std::sqrt(v[n + 1] * v[n + 1] + 2 * acceleration(v[n + 1], kappa[n]) * ds));
  }
  double time = 0.0;
  for (int n = 0; n < samples; ++n) time += 2 * ds / (v[n] + v[n + 1]);
  return time;
}

}  // namespace nupmpc::examples
