// The recursions against dense linear algebra (nup-algorithms.md §3.2 validation, issue
// test 1): for Gaussian-only problems one pass of each recursion equals the exact posterior.
#include <string>
#include <tuple>

#include "absl/strings/str_cat.h"
#include "core/algorithms/ibffd.h"
#include "core/algorithms/iffbdd.h"
#include "core/message_passing/forward_filter.h"
#include "core/message_passing/smoother.h"
#include "core/model/factor_graph.h"
#include "core/priors/scalar_rules.h"
#include "gtest/gtest.h"
#include "tests/util/dense_reference.h"
#include "tests/util/random_problem.h"

namespace nupmpc::core {
namespace {

using testing::DensePosterior;
using testing::RandomProblemSpec;

double RelError(const Eigen::MatrixXd& got, const Eigen::MatrixXd& want) {
  return (got - want).cwiseAbs().maxCoeff() / std::max(1.0, want.cwiseAbs().maxCoeff());
}

constexpr double kTolerance = 1e-9;

// (free x0, terminal prior, time-varying, seed)
class GaussianRecursions : public ::testing::TestWithParam<std::tuple<bool, bool, bool, int>> {
 protected:
  Problem MakeProblem() const {
    const auto [free_x0, terminal, time_varying, seed] = GetParam();
    RandomProblemSpec spec;
    spec.seed = static_cast<unsigned>(seed);
    spec.M = 1 + seed % 6;
    spec.L = 1 + seed % 3;
    spec.K = 1 + (seed * 7) % 4;
    spec.N = 5 + (seed * 13) % 36;
    spec.free_x0 = free_x0;
    spec.terminal = terminal;
    spec.time_varying = time_varying;
    spec.offsets = seed % 2 == 0;
    return testing::RandomGaussianProblem(spec);
  }
};

void ExpectSmootherEqualsDensePosterior(const Problem& p) {
  ASSERT_TRUE(Validate(p).ok());
  const DensePosterior dense = testing::SolveDense(p);
  const FactorGraph g = BuildFactorGraph(p, /*augment_inputs=*/false);
  std::vector<ScalarFactor> in(g.input_prior.size()), rows(g.num_rows());
  for (std::size_t i = 0; i < in.size(); ++i) in[i] = ScalarFactor::GaussianPart(g.input_prior[i]);
  for (int r = 0; r < g.num_rows(); ++r) rows[r] = ScalarFactor::GaussianPart(g.row_prior[r]);
  ForwardFilterWorkspace fw;
  fw.Resize(g, true);
  RunForwardFilter(g, in.data(), rows.data(), true, &fw);
  SmootherWorkspace sm;
  sm.Resize(g);
  RunSmootherBackward(g, fw, /*with_variances=*/true, &sm);

  EXPECT_LE(RelError(sm.mU, dense.u_mean), kTolerance);
  EXPECT_LE(RelError(sm.VU, dense.u_var), kTolerance);
  EXPECT_LE(RelError(sm.mX0, dense.x0_mean), kTolerance);
  EXPECT_LE(RelError(sm.VX0, dense.x0_cov), kTolerance);
  Eigen::MatrixXd mY(p.num_outputs, p.horizon + 1), VY(p.num_outputs, p.horizon + 1);
  for (int r = 0; r < g.num_rows(); ++r) {
    const RowOrigin& o = g.row_origin[r];
    if (o.type != RowOrigin::Type::kOutput) continue;
    mY(o.index, o.step) = sm.mY(r);
    VY(o.index, o.step) = sm.VY(r);
  }
  EXPECT_LE(RelError(mY, dense.y_mean), kTolerance);
  EXPECT_LE(RelError(VY, dense.y_var), kTolerance);
}

template <typename Algorithm>
void ExpectOnePassEqualsDenseMean(const Problem& p) {
  const DensePosterior dense = testing::SolveDense(p);
  Algorithm algorithm(p, SolverOptions{});
  PrimalIterate it;
  it.Resize(p.num_states, p.num_inputs, p.horizon);
  algorithm.Iterate(&it);
  EXPECT_LE(RelError(it.u, dense.u_mean), kTolerance);
  EXPECT_LE(RelError(it.x0, dense.x0_mean), kTolerance);
}

TEST_P(GaussianRecursions, SmootherEqualsDensePosterior) { ExpectSmootherEqualsDensePosterior(MakeProblem()); }
TEST_P(GaussianRecursions, OneIffbddPassEqualsDenseMean) { ExpectOnePassEqualsDenseMean<Iffbdd>(MakeProblem()); }
TEST_P(GaussianRecursions, OneIbffdPassEqualsDenseMean) { ExpectOnePassEqualsDenseMean<Ibffd>(MakeProblem()); }

INSTANTIATE_TEST_SUITE_P(RandomModels, GaussianRecursions,
                         ::testing::Combine(::testing::Bool(), ::testing::Bool(), ::testing::Bool(),
                                            ::testing::Range(1, 6)),
                         [](const auto& info) {
                           return std::string(std::get<0>(info.param) ? "FreeX0" : "FixedX0") +
                                  (std::get<1>(info.param) ? "_Terminal" : "_NoTerminal") +
                                  (std::get<2>(info.param) ? "_TimeVarying" : "_TimeInvariant") + "_" +
                                  std::to_string(std::get<3>(info.param));
                         });

// Every compiled state size (fixed_size.h) and dynamic sizes on either side of the largest,
// each against the dense posterior: a fixed-size kernel is its own code path.
class StateSizeKernels : public ::testing::TestWithParam<int> {
 protected:
  Problem MakeProblem() const {
    RandomProblemSpec spec;
    spec.seed = static_cast<unsigned>(100 + GetParam());
    spec.M = GetParam();
    spec.L = 3;
    spec.K = 4;
    spec.N = 12;
    spec.free_x0 = true;
    spec.terminal = true;
    spec.offsets = true;
    return testing::RandomGaussianProblem(spec);
  }
};

TEST_P(StateSizeKernels, SmootherEqualsDensePosterior) { ExpectSmootherEqualsDensePosterior(MakeProblem()); }
TEST_P(StateSizeKernels, OneIffbddPassEqualsDenseMean) { ExpectOnePassEqualsDenseMean<Iffbdd>(MakeProblem()); }
TEST_P(StateSizeKernels, OneIbffdPassEqualsDenseMean) { ExpectOnePassEqualsDenseMean<Ibffd>(MakeProblem()); }

INSTANTIATE_TEST_SUITE_P(CompiledAndDynamic, StateSizeKernels, ::testing::Values(8, 12, 16, 19, 20, 21, 40),
                         [](const auto& info) { return absl::StrCat("M", info.param); });

// A pinned (σ² = 0) input and a zero-variance output factor must be handled without 1/V.
TEST(ForwardFilter, PinnedFactorsAreExactAndFinite) {
  RandomProblemSpec spec;
  spec.M = 3;
  spec.N = 10;
  Problem p = testing::RandomGaussianProblem(spec);
  const FactorGraph g = BuildFactorGraph(p, false);
  std::vector<ScalarFactor> in(g.input_prior.size()), rows(g.num_rows());
  for (std::size_t i = 0; i < in.size(); ++i) in[i] = ScalarFactor::GaussianPart(g.input_prior[i]);
  for (int r = 0; r < g.num_rows(); ++r) rows[r] = ScalarFactor::GaussianPart(g.row_prior[r]);
  in[3] = ScalarFactor::Pinned(0.7);
  const int pinned_row = g.row_begin[4];
  rows[pinned_row] = ScalarFactor::Pinned(-0.2);
  ForwardFilterWorkspace fw;
  fw.Resize(g, true);
  RunForwardFilter(g, in.data(), rows.data(), true, &fw);
  SmootherWorkspace sm;
  sm.Resize(g);
  RunSmootherBackward(g, fw, true, &sm);
  EXPECT_NEAR(sm.mU(3 % g.L, 3 / g.L), 0.7, 1e-12);
  EXPECT_NEAR(sm.mY(pinned_row), -0.2, 1e-10);
  EXPECT_NEAR(sm.VY(pinned_row), 0.0, 1e-10);
  EXPECT_TRUE(sm.mU.allFinite() && sm.VU.allFinite() && sm.mY.allFinite());
}

}  // namespace
}  // namespace nupmpc::core
