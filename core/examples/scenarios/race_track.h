#ifndef NUPMPC_CORE_EXAMPLES_SCENARIOS_RACE_TRACK_H_
#define NUPMPC_CORE_EXAMPLES_SCENARIOS_RACE_TRACK_H_

// Minimal-time race track control ([KL] §V-E): the Ackermann vehicle in curvilinear
// coordinates with the arc length s as independent variable, model (108)–(110),
// discretised by Euler steps of length T_s (113)–(115), solved by sequential
// linearisation (core/nonlinear/nonlinear_model.h). State x = [z, θ, v, a, δ, t],
// input u = [dδ/dt, da/dt], outputs y = [z, a, δ, a² + ψ v⁴ tan²δ / ℓ²] (scaled, see
// RaceModel).
//
// The paper's bounds: |z| ≤ 0.006, |a| ≤ 1, |δ| ≤ 0.35, 0 ≤ a_tot² ≤ 150, ψ = 25; the
// terminal time has a zero-mean Gaussian prior with variance 500; the inputs a zero-mean
// Gaussian with variance 1e8 (unconstrained). The paper does not give its track or ℓ:
// ours is a closed loop of straights and circular arcs with tight hairpins, scaled so
// that these bounds matter (ℓ = 0.02; the tightest corner needs most of the steering
// range and the total-acceleration bound caps the corner speeds).

#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/nupmpc.h"
#include "core/public/nonlinear.h"

namespace nupmpc::examples {

// The bound on z, the distance from the centre line ([KL] §V-E).
inline constexpr double kTrackHalfWidth = 0.006;

// A closed centre line of pieces of constant curvature.
struct Track {
  struct Piece {
    double length;
    double curvature;  ///< 1/radius, > 0 turning left
  };
  std::vector<Piece> pieces;
  double length() const;
  double curvature_at(double s) const;  ///< s taken modulo the length
  // Centre-line point and heading at s, and the point displaced by z to the left.
  Eigen::Vector2d point(double s, double z = 0.0) const;
};

Track DemoTrack();

struct Vehicle {
  double length = 0.02;  ///< ℓ
  double psi = 25.0;     ///< ψ
};

// The spatial model of the vehicle on `track` with K steps over one lap. Its outputs are
// z, a, δ and a_tot² each divided by the largest magnitude of its bounds (0.006, 1, 0.35,
// 150), so that the step control compares their linearisation errors on one scale.
core::NonlinearModel RaceModel(const Track& track, const Vehicle& vehicle, int steps);
// a_tot² from the model's (scaled) outputs.
double TotalAccelerationSquared(const Eigen::VectorXd& outputs);

struct RaceRun {
  core::Solution plan;  ///< states (K+1)×6, inputs K×2, outputs (K+1)×4
  core::SequentialSummary summary;
  double lap_time = 0.0;              ///< t[K]
  double max_output_violation = 0.0;  ///< largest excess over the z, a, δ, a_tot² bounds
  double model_defect = 0.0;          ///< largest |x[n+1] - f(x[n], u[n])|
};

// How the lap is solved: sequential linearisation with a trust region on the speed (the
// state whose linearisation misleads most: dt/ds = 1/v) and Levenberg-Marquardt proximal
// terms on every state and input under the solver's step control. The plain Gauss-Newton
// sequence of [KL] diverges on our track: its first linearised problem is an almost-LP
// (the inputs are nearly free, the time cost nearly linear) that IFFBDD does not solve
// within 5000 passes, and full steps leave the linearisation's validity. The proximal
// terms vanish at a fixed point, so a converged lap solves the undamped problem.
struct RaceSettings {
  double start_speed = 0.3;          ///< v at the start line; the first guess drives the centre line at it
  double speed_trust_radius = 0.05;  ///< per linearisation
  double proximal_stddev = 30.0;     ///< initial σ of the proximal terms (states and inputs)
  core::SequentialOptions sequential = DefaultSequentialOptions();
  core::SolverOptions solver = DefaultSolverOptions();

  static core::SequentialOptions DefaultSequentialOptions();
  static core::SolverOptions DefaultSolverOptions();
};

// One lap from the start line (on the centre line, aligned, a = δ = 0).
absl::StatusOr<RaceRun> RaceLap(const Track& track, const Vehicle& vehicle, int steps,
                                const RaceSettings& settings = {});

// The lap time of a point mass on the centre line under the same speed, longitudinal and
// total-acceleration bounds (quasi-steady: the fastest speed profile along the fixed path,
// integrated on `samples` points). An independent reference: using the track's width, the
// race line must beat it.
double CentreLineLapTime(const Track& track, const Vehicle& vehicle, double start_speed, int samples);

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_SCENARIOS_RACE_TRACK_H_
