// M-level inputs as sums of binaries: the expanded model simulates exactly like the
// original one under the summed inputs; a three-level DAC input through IAKE lands on the
// levels and comes close to exhaustive search over all 3^K sequences.
#include "core/model/multilevel_inputs.h"

#include <cmath>

#include "core/examples/scenarios/dac.h"
#include "core/session/session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::core {
namespace {

constexpr int kN = 6;

// A double integrator with one multi-level thrust (input 0) and one ordinary input.
Problem Plant() {
  Problem p = Problem::TimeInvariant(2, 2, 1, kN);
  p.A[0] << 1.0, 0.5, 0.0, 1.0;
  p.B[0] << 0.125, 0.01, 0.5, 0.0;
  p.C[0] << 1.0, 0.0;
  p.initial_mean << 0.0, 0.0;
  p.input_priors.assign(static_cast<std::size_t>(kN) * 2, ScalarPrior::Free());
  for (int n = 0; n < kN; ++n) p.mutable_input_prior(n, 1) = ScalarPrior::Gaussian(0.0, 1.0);
  for (int n = 0; n <= kN; ++n) p.mutable_output_prior(n, 0) = ScalarPrior::Gaussian(n < 3 ? 0.6 : 1.4, 0.05);
  return p;
}

Eigen::VectorXd Simulate(const Problem& p, const Eigen::MatrixXd& u) {  // u: N × L; returns x[N]
  Eigen::VectorXd x = p.initial_mean;
  for (int n = 0; n < p.horizon; ++n) {
    Eigen::VectorXd next = p.A_at(n) * x + p.B_at(n) * u.row(n).transpose();
    for (int i = 0; i < p.num_states; ++i) next(i) += p.state_offset_at(n, i);
    x = next;
  }
  return x;
}

TEST(MultiLevelInputs, TheExpandedModelSimulatesLikeTheOriginal) {
  const Problem p = Plant();
  const std::vector<InputLevels> levels = {{.count = 4, .lowest = -1.5, .spacing = 1.0}, {}};
  auto e = ExpandMultiLevelInputs(p, levels);
  ASSERT_TRUE(e.ok()) << e.status();
  ASSERT_EQ(e->num_inputs, 3 + 1);
  Eigen::MatrixXd z = Eigen::MatrixXd::Random(kN, 4).cwiseAbs();  // any values, not only binary
  const Eigen::MatrixXd u = InputsFromLevels(z, levels);
  EXPECT_TRUE(Simulate(*e, z).isApprox(Simulate(p, u), 1e-12));
  for (int n = 0; n < kN; ++n) {
    for (int j = 0; j < 3; ++j) {
      const ScalarPrior& b = e->input_prior(n, j);
      EXPECT_EQ(b.kind, PriorKind::kBinary);
      EXPECT_EQ(b.initial_variance, 1.0 + 0.01 * j);  // symmetry breaking
    }
    EXPECT_TRUE(e->input_prior(n, 3).has_gaussian());  // the ordinary input keeps its prior
  }
}

using examples::DacTarget;

TEST(MultiLevelInputs, ThreeLevelDacComesCloseToExhaustiveSearch) {
  // The DAC of [KL] §V-A with a three-level input {0, 0.5, 1} (two binaries), receding
  // horizon K = 8, V_Y = 0.01: IAKE-EM (300 iterations, rounded) against all 3^8 sequences
  // per step, each controller from its own state.
  const int K = 8, steps = 60;
  const double VY = 0.01;
  Problem p = examples::DacPlant(K);
  const std::vector<InputLevels> levels = {{.count = 3, .lowest = 0.0, .spacing = 0.5}};
  const Eigen::Matrix3d A = p.A[0];
  const Eigen::Vector3d B = p.B[0];
  const Eigen::RowVector3d C = p.C[0];
  SolverOptions options;
  options.max_iterations = 300;
  Eigen::Vector3d x_nup = p.initial_mean, x_exh = p.initial_mean;
  double sse_nup = 0.0, sse_exh = 0.0;
  for (int t = 0; t < steps; ++t) {
    p.output_priors.assign(K + 1, ScalarPrior::Free());
    for (int n = 0; n <= K; ++n) p.output_priors[n] = ScalarPrior::Gaussian(DacTarget(t + n), VY);
    p.initial_mean.head<3>() = x_nup;  // at its fixed size (see View in core/message_passing/fixed_size.h)
    auto expanded = ExpandMultiLevelInputs(p, levels);
    ASSERT_TRUE(expanded.ok()) << expanded.status();
    auto session = Session::Create(*expanded, options);
    ASSERT_TRUE(session.ok()) << session.status();
    Solution plan;
    auto summary = (*session)->Solve(&plan);
    ASSERT_TRUE(summary.ok());
    const Eigen::MatrixXd u = InputsFromLevels(plan.inputs, levels);
    for (int n = 0; n < K; ++n) ASSERT_TRUE(u(n, 0) == 0.0 || u(n, 0) == 0.5 || u(n, 0) == 1.0) << u(n, 0);

    double best = INFINITY, best_u0 = 0.0;
    for (int code = 0; code < 6561; ++code) {  // 3^8
      Eigen::Vector3d x = x_exh;
      double cost = 0.0, u0 = 0.0;
      for (int n = 0, c = code; n < K; ++n, c /= 3) {
        const double level = 0.5 * (c % 3);
        if (n == 0) u0 = level;
        x = A * x + B * level;
        const double e = C * x - DacTarget(t + n + 1);
        cost += e * e;
      }
      if (cost < best) {
        best = cost;
        best_u0 = u0;
      }
    }
    x_nup = A * x_nup + B * u(0, 0);
    x_exh = A * x_exh + B * best_u0;
    sse_nup += std::pow(C * x_nup - DacTarget(t + 1), 2);
    sse_exh += std::pow(C * x_exh - DacTarget(t + 1), 2);
  }
  std::printf("DAC, 3 levels, K = 8: MSE IAKE-EM %.4e vs exhaustive %.4e (ratio %.3f)\n", sse_nup / steps,
              sse_exh / steps, sse_nup / sse_exh);
  EXPECT_LE(sse_nup, 1.10 * sse_exh);
}

TEST(MultiLevelInputs, BadLevelsAndOwnPriorsAreRefused) {
  const Problem p = Plant();
  EXPECT_THAT(ExpandMultiLevelInputs(p, {{.count = 1}, {}}).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("levels[0].count")));
  EXPECT_THAT(ExpandMultiLevelInputs(p, {{.count = 3, .spacing = -1.0}, {}}).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("levels[0]")));
  EXPECT_THAT(ExpandMultiLevelInputs(p, {{}, {.count = 3}}).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("input_priors[1]")));
  EXPECT_THAT(ExpandMultiLevelInputs(p, {{}}).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("levels")));
}

}  // namespace
}  // namespace nupmpc::core

namespace nupmpc::core {
namespace {

TEST(MultiLevelInputs, BinariesRoundedTogetherMustBeFollowedByAMatchingBinary) {
  Problem p = Plant();
  auto e = ExpandMultiLevelInputs(p, {{.count = 3, .lowest = -1.0, .spacing = 1.0}, {}});
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_TRUE(e->input_prior(0, 0).rounds_with_next);   // first of the two binaries
  EXPECT_FALSE(e->input_prior(0, 1).rounds_with_next);  // the last one closes the group
  Problem broken = *e;
  broken.mutable_input_prior(2, 1).rounds_with_next = true;  // followed by the Gaussian input
  EXPECT_THAT(Validate(broken), testing::StatusIs(absl::StatusCode::kInvalidArgument,
                                                  ::testing::HasSubstr("input_priors[7].rounds_with_next")));
}

}  // namespace
}  // namespace nupmpc::core
