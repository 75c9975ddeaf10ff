#include "loadtest/bench/gp/gp_closed_loop.h"

#include <cmath>
#include <random>

#include "core/examples/scenarios/gp_tanh.h"
#include "loadtest/bench/gp/ipopt_gp_mpc.h"

namespace nupmpc::bench {
namespace {

// The plant and its measurements; the same noise sequence for both loops.
struct Plant {
  explicit Plant(std::uint32_t seed) : rng(seed) {}
  double Apply(double u) {
    x = examples::TanhPlantStep(x, u);
    return x + noise(rng);
  }
  double x = 0.0;
  std::mt19937 rng;
  std::normal_distribution<double> noise{0.0, examples::kTanhNoiseStd};
};

Eigen::VectorXd ReferenceWindow(int t, int horizon) {
  Eigen::VectorXd r(horizon);
  for (int n = 0; n < horizon; ++n) r(n) = examples::TanhReference(t + n);
  return r;
}

void Finish(ClosedLoopTrace* trace) {
  trace->tracking_rmse = std::sqrt((trace->y - trace->reference).squaredNorm() / static_cast<double>(trace->y.size()));
}

}  // namespace

absl::StatusOr<GpComparison> RunGpClosedLoops(const gp::GpModel& model, const gp::GpMpcProblem& problem,
                                              const GpClosedLoopOptions& options) {
  if (problem.layout.output_lags != 1 || problem.layout.input_lags != 0) {
    return absl::InvalidArgumentError("problem.layout: the closed loop drives the [y[k-1], u[k]] tanh example");
  }
  const int H = problem.horizon, T = options.steps;
  GpComparison out;
  for (ClosedLoopTrace* trace : {&out.scp, &out.ipopt}) {
    trace->y = Eigen::VectorXd::Zero(T);
    trace->u = Eigen::VectorXd::Zero(T);
    trace->reference = Eigen::VectorXd::Zero(T);
  }

  // Loop A: linGP-SCP drives the plant.
  {
    absl::StatusOr<std::unique_ptr<gp::LinGpScp>> scp = gp::LinGpScp::Create(&model, problem);
    if (!scp.ok()) return scp.status();
    Plant plant(options.noise_seed);
    double y = 0.0, u = 0.0;
    for (int t = 0; t < T; ++t) {
      (*scp)->ShiftWarmStart();
      gp::ScpPlan plan;
      absl::StatusOr<gp::ScpSummary> s =
          (*scp)->Solve(Eigen::VectorXd::Constant(1, y), Eigen::VectorXd::Constant(1, u), ReferenceWindow(t, H), &plan);
      if (!s.ok()) return s.status();
      out.scp.step_seconds.push_back(s->seconds);
      out.scp.inner_seconds.push_back(s->inner_seconds);
      out.scp.unconverged += s->converged ? 0 : 1;
      out.scp.max_violation = std::max(out.scp.max_violation, s->max_violation);
      u = plan.inputs(0);
      y = plant.Apply(u);
      out.scp.u(t) = u;
      out.scp.y(t) = y;
      out.scp.reference(t) = examples::TanhReference(t);
    }
    Finish(&out.scp);
  }
  if (!options.with_ipopt) return out;

  // Loop B: Ipopt drives the plant; a shadow linGP-SCP solves the same problems.
  absl::StatusOr<std::unique_ptr<gp::LinGpScp>> shadow = gp::LinGpScp::Create(&model, problem);
  if (!shadow.ok()) return shadow.status();
  absl::StatusOr<std::unique_ptr<IpoptGpMpc>> ipopt =
      IpoptGpMpc::Create(&model, problem, IpoptGpMpcOptions{.tolerance = options.ipopt_tolerance});
  if (!ipopt.ok()) return ipopt.status();
  Plant plant(options.noise_seed);
  double y = 0.0, u = 0.0;
  Eigen::VectorXd warm = Eigen::VectorXd::Zero(H);
  for (int t = 0; t < T; ++t) {
    const Eigen::VectorXd past_y = Eigen::VectorXd::Constant(1, y), past_u = Eigen::VectorXd::Constant(1, u);
    const Eigen::VectorXd r = ReferenceWindow(t, H);
    // Ipopt starts from its previous plan shifted (the same warm start the SCP gets).
    absl::StatusOr<IpoptGpMpcResult> result = (*ipopt)->Solve(past_y, past_u, r, warm);
    if (!result.ok()) return result.status();
    out.ipopt.step_seconds.push_back(result->seconds);
    out.ipopt.unconverged += result->solved ? 0 : 1;

    (*shadow)->ShiftWarmStart();
    gp::ScpPlan plan;
    absl::StatusOr<gp::ScpSummary> s = (*shadow)->Solve(past_y, past_u, r, &plan);
    if (!s.ok()) return s.status();
    double j_ipopt = 0.0, violation = 0.0, j_scp = 0.0;
    (*shadow)->ExactMerit(result->inputs, nullptr, &j_ipopt, &violation);
    (*shadow)->ExactMerit(plan.inputs, nullptr, &j_scp, nullptr);
    out.ipopt.max_violation = std::max(out.ipopt.max_violation, violation);
    if (result->solved) {
      out.max_plan_difference = std::max(out.max_plan_difference, (plan.inputs - result->inputs).cwiseAbs().maxCoeff());
      out.max_objective_gap = std::max(out.max_objective_gap, (j_scp - j_ipopt) / std::max(1e-9, std::abs(j_ipopt)));
    }

    u = result->inputs(0);
    y = plant.Apply(u);
    out.ipopt.u(t) = u;
    out.ipopt.y(t) = y;
    out.ipopt.reference(t) = examples::TanhReference(t);
    warm.head(H - 1) = result->inputs.tail(H - 1);
    warm(H - 1) = result->inputs(H - 1);
  }
  Finish(&out.ipopt);
  return out;
}

}  // namespace nupmpc::bench
