#include "core/examples/scenarios/corridor.h"

#include <algorithm>
#include <cmath>

#include "core/examples/scenarios/timed_solve.h"
#include "core/public/input_maps.h"
#include "core/public/status_macros.h"

namespace nupmpc::examples {
namespace {

using core::ScalarPrior;

// Three levels: a soft corridor with slope 100. The paper's λ_o = 10 left the rounded,
// fixed and searched plan up to 0.02-0.2 outside (the penalty is too weak to be exact), a
// hard corridor 0.35 (the binaries cannot follow its pull).
constexpr double kThreeLevelCorridorSlope = 100.0;

// u[-1] = 0 for the Δu versions; the three levels {-1, 0, 1} of version 4.
Eigen::VectorXd NoPreviousInput() { return Eigen::VectorXd::Zero(1); }
std::vector<core::InputLevels> ThreeLevels() { return {{.count = 3, .lowest = -1.0, .spacing = 1.0}}; }

// Model (89) with the corridor as a hard box on y[1..K]; input priors left to the version.
core::Problem CorridorPlant(double slope) {
  core::Problem p = core::Problem::TimeInvariant(3, 1, 1, kCorridorSteps);
  p.A[0] << 1, 0, 0, 1, 1, 0, 0.5, 1, 1;
  p.B[0] << 0.0015, 0.0015 / 2, 0.0015 / 3;
  p.C[0] << 0, 0, 1;
  p.initial_mean = Eigen::Vector3d::Zero();
  for (int n = 1; n <= kCorridorSteps; ++n) {
    p.output_priors[n] =
        ScalarPrior::Box(CorridorTarget(n) - kCorridorHalfWidth, CorridorTarget(n) + kCorridorHalfWidth, slope);
  }
  return p;
}

}  // namespace

const char* CorridorVersionName(CorridorVersion version) {
  switch (version) {
    case CorridorVersion::kL2:
      return "l2_input";
    case CorridorVersion::kRateLimit:
      return "rate_limit";
    case CorridorVersion::kSparseInput:
      return "sparse_input";
    case CorridorVersion::kThreeLevels:
      return "three_levels";
    case CorridorVersion::kSparseChanges:
      return "sparse_changes";
  }
  return "unknown";
}

double CorridorTarget(int step) {
  // 0 until 20, ramp to 4 at 70, hold to 100, down to 1.6 at 130, hold.
  const auto ramp = [](double s, double from, double to) { return std::clamp((s - from) / (to - from), 0.0, 1.0); };
  return 4.0 * (ramp(step, 20, 70) - 0.6 * ramp(step, 100, 130));
}

absl::StatusOr<core::Problem> CorridorProblem(CorridorVersion version) {
  // Hard corridor, except for three levels (kThreeLevelCorridorSlope).
  const core::Problem plant =
      CorridorPlant(version == CorridorVersion::kThreeLevels ? kThreeLevelCorridorSlope : core::kInfinity);
  const int K = kCorridorSteps;
  const Eigen::VectorXd no_previous_input = NoPreviousInput();
  core::Problem problem = plant;
  switch (version) {
    case CorridorVersion::kL2:
      problem.input_priors.assign(K, ScalarPrior::Gaussian(0.0, 10.0));
      break;
    case CorridorVersion::kSparseInput:
      problem.input_priors.assign(K, ScalarPrior::PlainNuv(0.0));
      break;
    case CorridorVersion::kRateLimit: {
      // [KL]: only the half-space on Δu; a weak Gaussian on Δu picks one plan among the
      // many feasible ones.
      NUPMPC_ASSIGN_OR_RETURN(
          problem, core::AugmentWithInputDifferences(
                       plant, std::vector(K, ScalarPrior::AtLeast(-0.03).WithGaussian(0.0, 10.0)), no_previous_input));
      break;
    }
    case CorridorVersion::kSparseChanges: {
      NUPMPC_ASSIGN_OR_RETURN(problem, core::AugmentWithInputDifferences(
                                           plant, std::vector(K, ScalarPrior::PlainNuv(0.0)), no_previous_input));
      break;
    }
    case CorridorVersion::kThreeLevels: {
      NUPMPC_ASSIGN_OR_RETURN(problem, core::ExpandMultiLevelInputs(plant, ThreeLevels()));
      break;
    }
  }
  return problem;
}

absl::StatusOr<CorridorRun> RunCorridor(CorridorVersion version, int iterations) {
  const int K = kCorridorSteps;
  NUPMPC_ASSIGN_OR_RETURN(const core::Problem problem, CorridorProblem(version));
  NUPMPC_ASSIGN_OR_RETURN(const TimedPlan solved, SolveWithBudget(problem, iterations));
  const core::Solution& plan = solved.plan;
  CorridorRun run;
  run.seconds = solved.seconds;
  run.iterations = solved.summary.iterations;
  run.discrete_gap = solved.summary.discrete_gap;
  switch (version) {
    case CorridorVersion::kRateLimit:
    case CorridorVersion::kSparseChanges:
      run.inputs = core::InputsFromDifferences(plan.inputs, NoPreviousInput()).col(0);
      break;
    case CorridorVersion::kThreeLevels:
      run.inputs = core::InputsFromLevels(plan.inputs, ThreeLevels()).col(0);
      break;
    default:
      run.inputs = plan.inputs.col(0);
  }
  // Output 0 is y in every variant (Δu and M-level models keep the plant's outputs first),
  // evaluated by the session on the returned (rounded) plan.
  run.outputs = plan.outputs.col(0);
  run.min_input_change = core::kInfinity;
  double previous = 0.0;
  for (int n = 0; n < K; ++n) {
    const double u = run.inputs(n), change = u - previous;
    run.nonzero_inputs += std::abs(u) > 1e-3;
    run.input_switches += std::abs(change) > 1e-3;
    run.min_input_change = std::min(run.min_input_change, change);
    run.level_gap = std::max(run.level_gap, std::abs(u - std::round(std::clamp(u, -1.0, 1.0))));
    previous = u;
  }
  for (int n = 1; n <= K; ++n) {
    run.max_corridor_violation =
        std::max(run.max_corridor_violation, std::abs(run.outputs(n) - CorridorTarget(n)) - kCorridorHalfWidth);
  }
  run.max_corridor_violation = std::max(run.max_corridor_violation, 0.0);
  return run;
}

}  // namespace nupmpc::examples
