#ifndef NUPMPC_CLIENT_NONLINEAR_SESSION_H_
#define NUPMPC_CLIENT_NONLINEAR_SESSION_H_

// Nonlinear MPC through the v1 API: the client linearises, the server solves linear
// (LTV) problems. The plant is the user's discrete-time model
//
//   x[n+1] = f(t, x[n], u[n]),   y[n] = h(t, x[n])
//
// with Jacobians given by the user or taken by central finite differences. Each control
// period, Step() linearises along the previous plan shifted by one step,
//   A[n] = ∂f/∂x, B[n] = ∂f/∂u, c[n] = f(x̄, ū) − A x̄ − B ū,
//   C[n] = ∂h/∂x, d[n] = h(x̄) − C x̄,
// and sends one v1::Step with the measured state and the whole model (Step.model), warm
// started by a shift: a real-time iteration (RTI), the server keeping its NUP state across
// the changing model. With max_linearisations > 1 it re-linearises along each new plan and
// re-solves the same period (WARM_START_KEEP): sequential quadratic programming, with an
// optional trust region, Levenberg-Marquardt proximal terms and step control (the
// algorithm of core/nonlinear/sequential_solver.h, here on the client's side of the API).
//
//   nupmpc::Client client("127.0.0.1:50051");
//   nupmpc::NonlinearModel model = ...;       // f, h (and optionally their Jacobians)
//   v1::ProblemSpec spec = ...;               // horizon, x[0], priors, costs, keep_out, options
//   auto session = nupmpc::NonlinearSession::Create(client, model, spec);
//   auto plan = (*session)->Step(measured_x);  // apply plan->inputs[0..L-1]
//
// Plain std::vector<double> throughout (row-major matrices, step-major trajectories as in
// the proto): the client library has no linear-algebra dependency.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "client/client.h"
#include "client/nonlinear_model.h"
#include "core/public/standalone/step_control.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc {

// Keeps each linearised problem where its linear model is to be trusted (core
// TrustRegion, core/nonlinear/nonlinear_model.h). Per component; +∞ means none; empty
// means none for all. Implemented with extra outputs the session appends after the
// model's (a hard box around x̄_i for a radius; a Gaussian N(x̄_i, σ²) for a proximal
// term), and for inputs by folding N(ū, σ²) into the Gaussian part of their priors. The
// proximal terms vanish at a fixed point, so a converged SQP plan solves the undamped
// problem. Plans report the model's outputs only.
struct LinearisationRegion {
  std::vector<double> state_radius;           // M values > 0
  std::vector<double> state_proximal_stddev;  // M values > 0
  std::vector<double> input_proximal_stddev;  // L values > 0
};

// Levenberg-Marquardt step control of the proximal terms' widths within one period:
// StepControl (core/public/standalone/step_control.h), the rules core SequentialOptions.proximal_*
// use. Each solve's iteration cap is this period's own (max_iterations), so a solve that
// hit it is discarded. shrink = 1 (the default) turns it off.

struct NonlinearSessionOptions {
  // Linearisations (solves) per period: 1 is the real-time iteration; more re-linearise
  // along each new plan until it moves less than step_tolerance (max-norm of the change in
  // states and inputs over 1 + the plan's max-norm) with a converged solve.
  int max_linearisations = 1;
  double step_tolerance = 1e-6;
  // The warm start of each period's first solve. WARM_START_COLD re-solves every period
  // from scratch (same linearisation points): the baseline the warm start is measured
  // against. Later solves of a period always keep (WARM_START_KEEP).
  v1::WarmStart warm_start = v1::WARM_START_SHIFT;
  std::uint32_t max_iterations = 0;  // passes per solve (Step.max_iterations); 0: the spec's
  // Given Jacobians are checked against finite differences at every step of the initial
  // guess when the session is created (see CheckJacobians); Create() refuses a wrong one.
  bool check_jacobians = true;
  double jacobian_tolerance = 1e-5;
  double finite_difference_step = kDefaultFiniteDifferenceStep;
  LinearisationRegion region;
  StepControl step_control;
};

// The first linearisation point. Empty inputs: zeros (N×L); empty states: x[0] (the spec's
// initial_state.mean) held at every step ((N+1)×M), as a plant at rest. x[0] is always the
// spec's initial state.
struct InitialGuess {
  std::vector<double> inputs;
  std::vector<double> states;
};

// What one period cost.
struct PeriodReport {
  int linearisations = 0;  // linearised problems solved (one round trip each)
  int rejected = 0;        // of which the step control discarded
  int passes = 0;          // message-passing passes, summed over them (SolveResult.iterations)
  // Each solve's passes, in order: the first started as options.warm_start says, the later
  // ones of the period from the solve before (WARM_START_KEEP).
  std::vector<int> solve_passes;
  int keep_out_linearisations = 0;  // the server's own, for keep-out regions (SolveResult.linearisations)
  // RTI: the solve converged. SQP: besides, the plan settled within step_tolerance.
  bool converged = false;
  double last_step = 0.0;  // relative plan change at the last accepted linearisation
  // How far the plan is from the nonlinear model: max |x[n+1] − f(x[n], u[n])| and
  // max |y[n] − h(x[n])| over the horizon (0 for a linear plant).
  double model_defect = 0.0;
  double linearise_ms = 0.0;  // client: evaluating f, h and the Jacobians
  double solve_ms = 0.0;      // server: inside the solver (SolveResult.solve_ms), summed
  double period_ms = 0.0;     // the whole Step() call: linearising, round trips, solves
};

struct NonlinearPlan {
  // A controller applies inputs[0..L-1] only when true (see nupmpc::HasPlan).
  bool has_plan = false;
  std::vector<double> inputs;   // N×L, step-major
  std::vector<double> states;   // (N+1)×M
  std::vector<double> outputs;  // (N+1)×K: the linearised outputs C x + d the server planned
  v1::SolveResult result;       // the answer the plan came from (with the region's extra outputs)
  PeriodReport report;
};

class NonlinearSession {
 public:
  // Creates the server session (a Control stream owned by this object) from `spec`, whose
  // horizon, initial state, priors (on the model's K outputs), terminal cost, keep_out and
  // options are the user's; its model must carry the horizon and otherwise be empty (or
  // name the model's dimensions): the session fills in N matrices A, B and N+1 matrices C
  // linearised along `guess`, so the server stores the model per step from the start and
  // every later update keeps its warm start. INVALID_ARGUMENT naming the field for a bad
  // model, spec, options or guess, and for a given Jacobian that disagrees with finite
  // differences; the server's errors as they come. `client` must outlive the session (its
  // Control stream, closed with it, reconnects through the client).
  static absl::StatusOr<std::unique_ptr<NonlinearSession>> Create(Client& client, NonlinearModel model,
                                                                  v1::ProblemSpec spec,
                                                                  NonlinearSessionOptions options = {},
                                                                  InitialGuess guess = {});

  // One control period from `measured_state` (M values): linearises, solves (once, or up
  // to max_linearisations times) and returns the plan. `update` (references, bounds, a
  // shift) goes with the period's first solve; it may name the model's outputs only (the
  // linearisation region's come after them). A result without a plan is returned as such
  // (has_plan false). Errors: INVALID_ARGUMENT for a bad state or update (nothing sent),
  // and the server's refusals and broken model functions, prefixed "period P,
  // linearisation k: ". A refused first step leaves the session as it was; once the
  // server has taken it, the session has moved on one period whatever comes after.
  absl::StatusOr<NonlinearPlan> Step(const std::vector<double>& measured_state, const v1::PriorUpdate& update = {});

  // Checks the given Jacobians at every step of the point the next period will linearise
  // along (the shifted last plan, or the initial guess), as Create() does with the guess.
  absl::Status CheckJacobians() const;

  absl::Status Close() { return session_->Close(); }
  const std::string& session_id() const { return session_id_; }
  int horizon() const { return horizon_; }
  std::int64_t periods() const { return periods_; }
  const NonlinearModel& model() const { return model_; }

 private:
  struct Point {
    std::vector<double> states;  // (N+1)×M
    std::vector<double> inputs;  // N×L
  };
  NonlinearSession(NonlinearModel model, NonlinearSessionOptions options, v1::ProblemSpec base, int horizon);

  // The model linearised along `point` (absolute steps from t0), into `update` (a
  // ModelUpdate for Step, or written into the spec at creation).
  absl::Status LinearisedModel(const Point& point, std::int64_t t0, v1::ModelUpdate* update) const;
  // The region's priors around `point` at proximal `scale`: output entries for the extra
  // outputs, input entries merged with the base's Gaussian part.
  // `base` holds the user's input priors the merges start from.
  void RegionPriors(const Point& point, double scale, const v1::ProblemSpec& base, v1::PriorUpdate* update) const;
  // max |x[n+1] − f(x[n], u[n])|, max |y[n] − h(x[n])| along a plan (absolute steps from t0).
  absl::StatusOr<double> ModelDefect(const Point& plan, const std::vector<double>& outputs, std::int64_t t0) const;
  // The plan moved one step on: states and inputs n+1 → n, the last input repeated and the
  // last state propagated through f.
  absl::StatusOr<Point> Shifted(const Point& plan, std::int64_t t0) const;
  Point PlanPoint(const v1::SolveResult& result) const;
  std::vector<double> ModelOutputs(const v1::SolveResult& result) const;
  int extra_outputs() const { return static_cast<int>(trusted_.size() + damped_.size()); }

  NonlinearModel model_;
  NonlinearSessionOptions options_;
  v1::ProblemSpec base_;  // the user's priors as the server holds them (updates applied), for the input merges
  int horizon_;
  std::vector<std::pair<int, double>> trusted_;        // (state, radius): extra outputs K, K+1, ...
  std::vector<std::pair<int, double>> damped_;         // (state, σ): the extra outputs after them
  std::vector<std::pair<int, double>> damped_inputs_;  // (input, σ)
  std::unique_ptr<Session> session_;
  std::string session_id_;
  Point next_point_;  // where the next period linearises (before x[0] is set to the measurement)
  std::int64_t periods_ = 0;
};

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_NONLINEAR_SESSION_H_
