#ifndef NUPMPC_CORE_EXAMPLES_SCENARIOS_RACE_TRACK_H_
#define NUPMPC_CORE_EXAMPLES_SCENARIOS_RACE_TRACK_H_

// Minimal-time race track control ([KL] §V-E): the Ackermann vehicle in curvilinear
// coordinates with the arc length s as independent variable, model (108)–(110),
// discretised by Euler steps of length T_s (113)–(115), solved by sequential
// linearisation (core/nonlinear/nonlinear_model.h). State x = [z, θ, v, a, δ, t],
// input u = [dδ/dt, da/dt], outputs y = [z, a, δ, a² + ψ v⁴ tan²δ / ℓ²].
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
#include "core/nonlinear/nonlinear_model.h"
#include "core/nonlinear/sequential_solver.h"

namespace nupmpc::examples {

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

// The spatial model of the vehicle on `track` with K steps over one lap.
core::NonlinearModel RaceModel(const Track& track, const Vehicle& vehicle, int steps);

struct RaceRun {
  core::Solution plan;            ///< states (K+1)×6, inputs K×2, outputs (K+1)×4
  core::SequentialSummary summary;
  double lap_time = 0.0;          ///< t[K]
  double max_output_violation = 0.0;  ///< largest excess over the z, a, δ, a_tot² bounds
  double model_defect = 0.0;      ///< largest |x[n+1] - f(x[n], u[n])|
};

// One lap from the start line at speed v0 (on the centre line, aligned, a = δ = 0),
// starting from driving the centre line at v0.
// `speed_trust_radius` bounds how far each linearisation may move the speed (the only
// state whose linearisation misleads: dt/ds = 1/v).
absl::StatusOr<RaceRun> RaceLap(const Track& track, const Vehicle& vehicle, int steps, double v0,
                                double speed_trust_radius, core::SequentialOptions options = {});

}  // namespace nupmpc::examples

#endif  // NUPMPC_CORE_EXAMPLES_SCENARIOS_RACE_TRACK_H_
