#include "core/examples/scenarios/dac.h"

#include <chrono>
#include <cmath>
#include <numbers>
#include <utility>

#include "Eigen/LU"
#include "core/examples/scenarios/timed_solve.h"
#include "core/public/session.h"
#include "core/public/status_macros.h"

namespace nupmpc::examples {
namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// The first input of the best binary sequence over `window` steps from x (all 2^window).
double ExhaustiveFirstInput(const core::Problem& plant, const Eigen::Vector3d& x0, int window, int first_step,
                            double frequency_hz) {
  const Eigen::Matrix3d A = plant.A[0];
  const Eigen::Vector3d B = plant.B[0];
  const Eigen::RowVector3d C = plant.C[0];
  double best_cost = INFINITY, best_u0 = 0.0;
  for (int code = 0; code < (1 << window); ++code) {
    Eigen::Vector3d x = x0;
    double cost = 0.0;
    for (int n = 0; n < window && cost < best_cost; ++n) {
      x = A * x + B * ((code >> n) & 1);
      const double e = C * x - DacTarget(first_step + n + 1, frequency_hz);
      cost += e * e;
    }
    if (cost < best_cost) {
      best_cost = cost;
      best_u0 = code & 1;
    }
  }
  return best_u0;
}

}  // namespace

core::Problem DacPlant(int K) {
  core::Problem p = core::Problem::TimeInvariant(3, 1, 1, K);
  p.A[0] << 0.7967, -6.3978, -94.2123, 0.0027, 0.9902, -0.1467, 0.0, 0.0030, 0.9999;
  p.B[0] << 0.0027, 0.0, 0.0;
  p.C[0] << 0.0, 0.0, 35037.9;
  p.initial_mean = (Eigen::Matrix3d::Identity() - p.A[0]).partialPivLu().solve(0.5 * p.B[0]);
  return p;
}

double DacTarget(int step, double frequency_hz) {
  return 0.8967 * 0.5 + 0.3 * std::sin(2.0 * std::numbers::pi * frequency_hz * kDacSamplePeriod * step);
}

core::Problem DacWindow(int K, double output_variance, int first_step, double frequency_hz, bool em) {
  core::Problem p = DacPlant(K);
  p.input_priors.assign(K, core::ScalarPrior::Binary(0.0, 1.0, em));
  for (int n = 0; n <= K; ++n) {
    p.output_priors[n] = core::ScalarPrior::Gaussian(DacTarget(first_step + n, frequency_hz), output_variance);
  }
  return p;
}

absl::StatusOr<DacPlan> DacLongPlan(int K, double output_variance, double frequency_hz, int iterations, bool em) {
  NUPMPC_ASSIGN_OR_RETURN(const TimedPlan solved,
                          SolveWithBudget(DacWindow(K, output_variance, 0, frequency_hz, em), iterations));
  DacPlan result;
  result.seconds = solved.seconds;
  result.inputs = solved.plan.inputs.col(0);
  result.outputs = solved.plan.outputs.col(0);
  result.target.resize(K + 1);
  for (int n = 0; n <= K; ++n) result.target(n) = DacTarget(n, frequency_hz);
  result.mse = (result.outputs - result.target).segment(1, K - 2).squaredNorm() / (K - 2);
  result.iterations = solved.summary.iterations;
  result.discrete_gap = solved.summary.discrete_gap;
  return result;
}

absl::StatusOr<DacOnlineRun> DacOnline(int window, int steps, double output_variance, double frequency_hz,
                                       int iterations) {
  core::Problem p = DacWindow(window, output_variance, 0, frequency_hz);
  core::SolverOptions options;
  options.max_iterations = iterations;  // a budget: EM stops early only once every input is binary
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<core::Session> session, core::Session::Create(p, options));
  const Eigen::Matrix3d A = p.A[0];
  const Eigen::Vector3d B = p.B[0];
  const Eigen::RowVector3d C = p.C[0];
  Eigen::Vector3d x_nup = p.initial_mean;
  DacOnlineRun run;
  run.nup_inputs.resize(steps);
  run.nup_outputs.resize(steps);
  core::Solution plan;
  core::SolveLimits cold;
  cold.warm_start = false;
  for (int t = 0; t < steps; ++t) {
    for (int n = 0; n <= window; ++n) {
      p.output_priors[n] = core::ScalarPrior::Gaussian(DacTarget(t + n, frequency_hz), output_variance);
    }
    p.initial_mean.head<3>() = x_nup;  // at its fixed size (see View in core/message_passing/fixed_size.h)
    NUPMPC_RETURN_IF_ERROR(session->Update(p));
    const auto start = std::chrono::steady_clock::now();
    NUPMPC_ASSIGN_OR_RETURN(const core::SolveSummary summary, session->Solve(cold, &plan));
    run.nup_seconds += Seconds(start);
    run.largest_gap = std::max(run.largest_gap, summary.discrete_gap);
    run.nup_inputs(t) = plan.inputs(0, 0);
    x_nup = A * x_nup + B * run.nup_inputs(t);
    run.nup_outputs(t) = C * x_nup;
  }
  DacExhaustiveRun exhaustive = RunDacExhaustive(window, steps, frequency_hz);
  run.exhaustive_inputs = std::move(exhaustive.inputs);
  run.exhaustive_outputs = std::move(exhaustive.outputs);
  run.target = std::move(exhaustive.target);
  run.exhaustive_mse = exhaustive.mse;
  run.nup_mse = (run.nup_outputs - run.target).squaredNorm() / steps;
  return run;
}

DacExhaustiveRun RunDacExhaustive(int window, int steps, double frequency_hz) {
  const core::Problem p = DacPlant(window);
  Eigen::Vector3d x = p.initial_mean;
  DacExhaustiveRun run;
  run.inputs.resize(steps);
  run.outputs.resize(steps);
  run.target.resize(steps);
  for (int t = 0; t < steps; ++t) {
    run.inputs(t) = ExhaustiveFirstInput(p, x, window, t, frequency_hz);
    x = p.A[0] * x + p.B[0] * run.inputs(t);
    run.outputs(t) = p.C[0].row(0).dot(x);
    run.target(t) = DacTarget(t + 1, frequency_hz);
  }
  run.mse = (run.outputs - run.target).squaredNorm() / steps;
  return run;
}

}  // namespace nupmpc::examples
