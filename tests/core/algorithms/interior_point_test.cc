// The interior-point iteration IFFBDD runs on problems whose only constraints are hard
// output bounds (core/algorithms/interior_point_rows.h): its means pass against the full
// Kalman filter, its solves against reference.json and against IFFBDD's own dual
// iteration, and its pass counts on the instances where IFFBDD's dual iteration is slowest.
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "core/algorithms/interior_point_rows.h"
#include "core/message_passing/forward_filter.h"
#include "core/model/factor_graph.h"
#include "core/session/session.h"
#include "gtest/gtest.h"
#include "loadtest/instances/benchmark_instance.h"
#include "tests/util/random_problem.h"

namespace nupmpc::core {
namespace {

const std::string kDir = NUPMPC_BENCHMARK_DIR;

// A means pass with new ξ and the precisions of the last full pass gives the full filter's
// predictions and gains for the new ξ (the corrector's second right-hand side).
TEST(InteriorPoint, MeansPassMatchesTheFullFilterForNewLinearTerms) {
  auto inst = bench::LoadBenchmarkInstance(kDir + "/random_outbox_M40_K20_L20_N1000_s1.json");
  ASSERT_TRUE(inst.ok()) << inst.status();
  inst->problem.horizon = 60;  // the first 60 steps are a problem of their own
  inst->problem.input_priors.resize(60 * inst->problem.num_inputs);
  inst->problem.output_priors.resize(61 * inst->problem.num_outputs);
  const FactorGraph graph = BuildFactorGraph(inst->problem, /*augment_inputs=*/false);
  std::vector<ScalarFactor> inputs(graph.input_prior.size()), first(graph.num_rows()), second(graph.num_rows());
  for (std::size_t i = 0; i < inputs.size(); ++i) inputs[i] = ScalarFactor::GaussianPart(graph.input_prior[i]);
  for (int r = 0; r < graph.num_rows(); ++r) {
    const double w = 1.0 + 0.5 * std::sin(r), xi = std::cos(3.0 * r);
    first[r] = ScalarFactor::Canonical(xi, w);
    second[r] = ScalarFactor::Canonical(-2.0 * xi + 0.1 * r / graph.num_rows(), w);
  }
  ForwardFilterWorkspace means, full;
  means.Resize(graph, false);
  full.Resize(graph, false);
  RunForwardFilter(graph, inputs.data(), first.data(), false, &means);
  RunForwardMeans(graph, second.data(), &means);
  RunForwardFilter(graph, inputs.data(), second.data(), false, &full);
  const double scale = full.yhat.cwiseAbs().maxCoeff();
  ASSERT_GT(scale, 0.0);
  EXPECT_LE((means.yhat - full.yhat).cwiseAbs().maxCoeff(), 1e-12 * scale);
  EXPECT_LE((means.g - full.g).cwiseAbs().maxCoeff(), 1e-12 * full.g.cwiseAbs().maxCoeff());
  // The first pass's ξ left different means: the comparison is not vacuous.
  ForwardFilterWorkspace old;
  old.Resize(graph, false);
  RunForwardFilter(graph, inputs.data(), first.data(), false, &old);
  EXPECT_GT((old.yhat - full.yhat).cwiseAbs().maxCoeff(), 1e-3 * scale);
}

TEST(InteriorPoint, HandlesHardBoundsWhoseStartIsRepresentable) {
  EXPECT_TRUE(InteriorPointHandles(ScalarPrior::Free()));
  EXPECT_TRUE(InteriorPointHandles(ScalarPrior::Gaussian(1.0, 2.0)));
  EXPECT_TRUE(InteriorPointHandles(ScalarPrior::Box(-1.0, 1.0)));
  EXPECT_TRUE(InteriorPointHandles(ScalarPrior::AtLeast(-1.0)));
  EXPECT_TRUE(InteriorPointHandles(ScalarPrior::AtMost(1.0).WithGaussian(0.5, 2.0)));
  EXPECT_FALSE(InteriorPointHandles(ScalarPrior::Box(-1.0, 1.0, /*slope=*/5.0)));  // soft: an exact penalty
  EXPECT_FALSE(InteriorPointHandles(ScalarPrior::L1(0.0, 1.0)));
  EXPECT_FALSE(InteriorPointHandles(ScalarPrior::Box(0.0, 1e-160)));    // 6/w² overflows
  EXPECT_FALSE(InteriorPointHandles(ScalarPrior::Box(-1e160, 1e160)));  // 6/w² underflows
}

struct Solved {
  SolveSummary summary;
  Solution plan;
};

Solved SolveCold(const Problem& problem, bool interior_point) {
  SolverOptions options;
  options.interior_point = interior_point;
  auto session = Session::Create(problem, options);
  EXPECT_TRUE(session.ok()) << session.status();
  Solved out;
  auto summary = (*session)->Solve(SolveLimits{}, &out.plan);
  EXPECT_TRUE(summary.ok()) << summary.status();
  out.summary = *summary;
  return out;
}

// Exact to the references in at most the passes that make it worth its cost (12 on the
// random output boxes, 20 on the corridor: IFFBDD's dual iteration needs 18–29 and 41),
// and the same optimum as IFFBDD's own iteration.
TEST(InteriorPoint, SolvesTheOutputBoxInstancesExactlyInFewPasses) {
  auto refs = bench::LoadReferences(kDir + "/reference.json");
  ASSERT_TRUE(refs.ok()) << refs.status();
  const std::map<std::string, int> max_passes = {{"random_outbox_M40_K20_L20_N1000_s1", 12},
                                                 {"random_outbox_M40_K20_L20_N1000_s2", 12},
                                                 {"random_outbox_M40_K20_L20_N1000_s3", 12},
                                                 {"corridor_N175", 20}};
  for (const auto& [name, passes] : max_passes) {
    auto inst = bench::LoadBenchmarkInstance(kDir + "/" + name + ".json");
    ASSERT_TRUE(inst.ok()) << inst.status();
    const double J_star = refs->at(name).J_star;
    const Solved ipm = SolveCold(inst->problem, /*interior_point=*/true);
    EXPECT_EQ(ipm.summary.status, SolveStatus::kConverged) << name << ": " << ipm.summary.Describe();
    EXPECT_TRUE(ipm.summary.polished) << name;
    EXPECT_LE(ipm.summary.iterations, passes) << name;
    EXPECT_LE(std::abs(ipm.summary.objective - J_star), 1e-9 * std::abs(J_star)) << name;
    EXPECT_LE(ipm.summary.max_violation, 1e-9) << name;
    const Solved dual = SolveCold(inst->problem, /*interior_point=*/false);
    EXPECT_GT(dual.summary.iterations, passes) << name << ": the dual iteration got faster; is the test still useful?";
    EXPECT_LE(std::abs(ipm.summary.objective - dual.summary.objective), 1e-9 * std::abs(J_star)) << name;
    EXPECT_LE((ipm.plan.inputs - dual.plan.inputs).cwiseAbs().maxCoeff(),
              1e-6 * (1.0 + dual.plan.inputs.cwiseAbs().maxCoeff()))
        << name;
  }
}

// After an interior-point solve the accepted regions are carried: re-solving the same
// problem warm is one polish pass, and a warm solve for a moved x[0] (which continues with
// IFFBDD's own iteration once its first polish fails) reaches the cold solve's optimum.
TEST(InteriorPoint, WarmSolvesStartFromTheAcceptedRegions) {
  auto inst = bench::LoadBenchmarkInstance(kDir + "/corridor_N175.json");
  ASSERT_TRUE(inst.ok()) << inst.status();
  auto session = Session::Create(inst->problem, SolverOptions{});
  ASSERT_TRUE(session.ok()) << session.status();
  auto cold = (*session)->Solve(SolveLimits{}, nullptr);
  ASSERT_TRUE(cold.ok());
  ASSERT_TRUE(cold->polished);
  SolveLimits warm_limits;
  warm_limits.warm_start = true;
  auto again = (*session)->Solve(warm_limits, nullptr);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->iterations, 1);
  EXPECT_TRUE(again->polished);
  EXPECT_NEAR(again->objective, cold->objective, 1e-9 * std::abs(cold->objective));

  Problem moved = inst->problem;
  moved.initial_mean(2) += 0.02;  // the output starts 0.02 up in a corridor of half-width 0.1
  ASSERT_TRUE((*session)->SetInitialState(moved.initial_mean).ok());
  auto warm = (*session)->Solve(warm_limits, nullptr);
  ASSERT_TRUE(warm.ok());
  const Solved reference = SolveCold(moved, /*interior_point=*/false);
  EXPECT_EQ(warm->status, SolveStatus::kConverged) << warm->Describe();
  EXPECT_NEAR(warm->objective, reference.summary.objective, 1e-9 * std::abs(reference.summary.objective));
  EXPECT_LE(warm->max_violation, 1e-9);
}

// Two outputs of the same state with disjoint boxes: no plan meets both. The interior point
// stalls and hands the solve to IFFBDD's iteration, whose watch reports the empty set far
// below the iteration cap with a finite plan (not a stalled iterate taken for converged).
TEST(InteriorPoint, AnEmptyOutputSetIsReportedInfeasible) {
  Problem p = Problem::TimeInvariant(1, 1, 2, 30);
  p.A[0] << 1;
  p.B[0] << 1;
  p.C[0] << 1, 1;
  p.initial_mean = Eigen::VectorXd::Zero(1);
  for (ScalarPrior& prior : p.input_priors) prior = ScalarPrior::Gaussian(0.0, 1.0);
  for (int n = 1; n <= 30; ++n) {
    p.mutable_output_prior(n, 0) = ScalarPrior::Box(0.0, 1.0);
    p.mutable_output_prior(n, 1) = ScalarPrior::Box(2.0, 3.0);
  }
  SolverOptions options;
  auto session = Session::Create(p, options);
  ASSERT_TRUE(session.ok()) << session.status();
  Solution plan;
  auto s = (*session)->Solve(SolveLimits{}, &plan);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->status, SolveStatus::kInfeasible) << s->Describe();
  EXPECT_LT(s->iterations, options.max_iterations / 10) << s->Describe();
  EXPECT_TRUE(s->has_plan);
  EXPECT_TRUE(plan.inputs.allFinite());
  EXPECT_GT(s->max_violation, 0.4);  // at best the state sits between the boxes, 0.5 from each
}

// Half-spaces, and bounds with a Gaussian part (a tracking cost) on the same row: the
// interior point reaches IFFBDD's optimum.
TEST(InteriorPoint, HalfSpacesAndBoundsWithACostMatchIffbdd) {
  auto inst = bench::LoadBenchmarkInstance(kDir + "/corridor_N175.json");
  ASSERT_TRUE(inst.ok()) << inst.status();
  Problem p = inst->problem;
  for (int n = 1; n <= p.horizon; ++n) {
    const ScalarPrior box = p.output_prior(n, 0);
    if (!box.is_constraint()) continue;
    const double centre = 0.5 * (box.lower + box.upper);
    // Alternating one-sided corridors, every other step with a pull to the centre line.
    ScalarPrior bound = n % 2 == 0 ? ScalarPrior::AtLeast(box.lower) : ScalarPrior::AtMost(box.upper);
    if (n % 3 == 0) bound = box.WithGaussian(centre, 0.01);
    p.mutable_output_prior(n, 0) = bound;
  }
  const Solved ipm = SolveCold(p, /*interior_point=*/true);
  const Solved dual = SolveCold(p, /*interior_point=*/false);
  EXPECT_EQ(ipm.summary.status, SolveStatus::kConverged) << ipm.summary.Describe();
  EXPECT_EQ(dual.summary.status, SolveStatus::kConverged) << dual.summary.Describe();
  EXPECT_LT(ipm.summary.iterations, dual.summary.iterations);
  EXPECT_LE(std::abs(ipm.summary.objective - dual.summary.objective), 1e-9 * std::abs(dual.summary.objective));
  EXPECT_LE(ipm.summary.max_violation, 1e-9);
}

// The objectives of every pass of a cold solve.
std::vector<double> PassObjectives(Session& session) {
  std::vector<double> objectives;
  SolveLimits cold;
  cold.warm_start = false;
  cold.trace = [&](const PassTrace& t) {
    if (t.kind == PassTrace::Kind::kIterate) objectives.push_back(t.objective);
  };
  const absl::StatusOr<SolveSummary> solved = session.Solve(cold, nullptr);
  EXPECT_TRUE(solved.ok()) << solved.status();
  return objectives;
}

// A row whose bound an update removed is never started again: nothing of its earlier
// solve's barrier may enter the next solve's Newton passes.
TEST(InteriorPoint, ARowWhoseBoundAnUpdateRemovedLeavesTheMethod) {
  const testing::RandomProblemSpec spec{.M = 4, .L = 2, .K = 3, .N = 20, .terminal = false, .seed = 3};
  const Problem bounded = testing::WithBoxes(testing::RandomGaussianProblem(spec), 0.0, 2.0);
  Problem unbounded_from_3 = bounded;
  int removed = 0;
  for (int n = 3; n <= spec.N; ++n) {
    for (int k = 0; k < spec.K; ++k) {
      ScalarPrior& prior = unbounded_from_3.mutable_output_prior(n, k);
      if (!prior.is_constraint()) continue;
      prior = ScalarPrior::Gaussian(prior.mean, prior.variance);
      ++removed;
    }
  }
  ASSERT_GT(removed, 0);
  SolverOptions options;
  options.algorithm = Algorithm::kIffbdd;
  auto updated = Session::Create(bounded, options);
  ASSERT_TRUE(updated.ok()) << updated.status();
  const std::vector<double> before = PassObjectives(**updated);
  ASSERT_TRUE((*updated)->Update(unbounded_from_3).ok());
  auto fresh = Session::Create(unbounded_from_3, options);
  ASSERT_TRUE(fresh.ok()) << fresh.status();
  const std::vector<double> want = PassObjectives(**fresh);
  const std::vector<double> got = PassObjectives(**updated);
  ASSERT_FALSE(want.empty());
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < want.size(); ++i) {
    EXPECT_NEAR(got[i], want[i], 1e-12 * std::abs(want[i])) << "pass " << i + 1;
  }
  EXPECT_NE(before, want);  // the update changed the problem's iterates
}

}  // namespace
}  // namespace nupmpc::core
