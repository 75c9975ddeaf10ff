#ifndef NUPMPC_CLIENT_EXAMPLES_RACE_TRACK_H_
#define NUPMPC_CLIENT_EXAMPLES_RACE_TRACK_H_

// The minimal-time race-track lap of [KL] §V-E through the v1 API: the client linearises
// the vehicle's spatial model (NonlinearSession, SQP with the same trust region, proximal
// terms and step control as the core example), the server solves the linearised problems.
//
// The client may not include the core, so the track and the model are written here again
// in plain vectors: the same numbers as core/examples/scenarios/race_track.{h,cc}
// (DemoTrack, RaceModel, RaceSettings), which tests/client/race_track_api_test.cc checks
// point by point before comparing the two laps.

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "client/client.h"
#include "client/nonlinear_session.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::api_examples {

// A closed centre line of pieces of constant curvature.
struct Track {
  struct Piece {
    double length;
    double curvature;  // 1/radius, > 0 turning left
  };
  std::vector<Piece> pieces;
  double length() const;
  double curvature_at(double s) const;  // s taken modulo the length
};

// The core example's DemoTrack: a rounded 1.2 × 0.7 rectangle with an S-chicane.
Track DemoTrack();

struct Vehicle {
  double length = 0.02;  // ℓ
  double psi = 25.0;     // ψ
};

// The spatial model with K = `steps` Euler steps over one lap: x = [z, θ, v, a, δ, t],
// u = [dδ/dt, da/dt], y = [z, a, δ, a² + ψ v⁴ tan²δ / ℓ²] each divided by its bound
// (0.006, 1, 0.35, 150). The step index t of the model is the spatial step n (one lap is
// one period). Analytic Jacobians.
NonlinearModel RaceModel(const Track& track, const Vehicle& vehicle, int steps);

// The lap's problem: x[0] on the start line at `start_speed`, the paper's bounds on the
// outputs at steps 1..K, inputs nearly free (Gaussian, variance 1e8), lap time t[K] with a
// zero-mean Gaussian prior of variance 500 (terminal cost), and the core example's solver
// tolerances.
v1::ProblemSpec RaceSpec(int steps, double start_speed);

// The first guess: the centre line at the start speed, steering along the curvature.
InitialGuess RaceGuess(const Track& track, const Vehicle& vehicle, int steps, double start_speed);

// The core example's RaceSettings: trust region on the speed, proximal terms on every
// state and input, Levenberg-Marquardt step control.
struct RaceSettings {
  double start_speed = 0.3;
  double speed_trust_radius = 0.05;
  double proximal_stddev = 30.0;
  int max_linearisations = 300;
};
NonlinearSessionOptions RaceOptions(const RaceSettings& settings);

struct RaceLapRun {
  double lap_time = 0.0;              // t[K]
  double max_output_violation = 0.0;  // largest excess over the z, a, δ, a_tot² bounds, on h(x) of the plan
  PeriodReport report;                // linearisations, passes, times of the whole lap
  std::vector<double> states;         // (K+1)×6
};

// One lap through `client`'s server.
absl::StatusOr<RaceLapRun> RunRaceLap(Client& client, const Track& track, const Vehicle& vehicle, int steps,
                                      const RaceSettings& settings = {});

}  // namespace nupmpc::api_examples

#endif  // NUPMPC_CLIENT_EXAMPLES_RACE_TRACK_H_
