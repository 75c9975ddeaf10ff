// Priors on input differences through model augmentation: with Gaussian priors the plan
// equals the dense least-squares solution of the original problem with a Δu penalty
// (built here from the model directly, not through the augmentation); rate limits and
// input boxes hold together; bad arguments name the field.
#include "core/model/input_differences.h"

#include "Eigen/Dense"
#include "core/session/session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/status_matchers.h"

namespace nupmpc::core {
namespace {

constexpr int kN = 15;

Problem SmallPlant() {
  Problem p = Problem::TimeInvariant(2, 1, 1, kN);
  p.A[0] << 1.0, 0.1, 0.0, 0.98;
  p.B[0] << 0.005, 0.1;
  p.C[0] << 1.0, 0.0;
  p.initial_mean << -0.4, 0.0;
  p.input_priors.assign(kN, ScalarPrior::Gaussian(0.0, 1.0 / 0.1));        // ½·0.1·u²
  p.output_priors.assign(kN + 1, ScalarPrior::Gaussian(1.0, 1.0 / 50.0));  // ½·50·(y - 1)²
  return p;
}

TEST(InputDifferences, GaussianPlanEqualsTheDenseLeastSquaresSolution) {
  const Problem p = SmallPlant();
  const double w_delta = 20.0, u_prev = 0.3;
  auto augmented = AugmentWithInputDifferences(
      p, std::vector<ScalarPrior>(kN, ScalarPrior::Gaussian(0.0, 1.0 / w_delta)), Eigen::VectorXd::Constant(1, u_prev));
  ASSERT_TRUE(augmented.ok()) << augmented.status();
  auto session = Session::Create(*augmented);
  ASSERT_TRUE(session.ok()) << session.status();
  Solution plan;
  auto summary = (*session)->Solve(&plan);
  ASSERT_TRUE(summary.ok());
  const Eigen::MatrixXd u = InputsFromDifferences(plan.inputs, Eigen::VectorXd::Constant(1, u_prev));

  // Dense reference over u[0..N-1]: y[n] = C Aⁿ x0 + Σ_{k<n} C A^{n-1-k} B u[k].
  const Eigen::MatrixXd& A = p.A[0];
  const Eigen::MatrixXd& B = p.B[0];
  const Eigen::MatrixXd& C = p.C[0];
  Eigen::MatrixXd Phi = Eigen::MatrixXd::Zero(kN + 1, kN);
  Eigen::VectorXd free_response(kN + 1);
  Eigen::VectorXd x = p.initial_mean;
  for (int n = 0; n <= kN; ++n) {
    free_response(n) = (C * x)(0);
    x = A * x;
    for (int k = 0; k < n; ++k) {
      Eigen::MatrixXd Ak = Eigen::MatrixXd::Identity(2, 2);
      for (int j = 0; j < n - 1 - k; ++j) Ak = A * Ak;
      Phi(n, k) = (C * Ak * B)(0);
    }
  }
  Eigen::MatrixXd D = Eigen::MatrixXd::Zero(kN, kN);  // (D u)[n] = u[n] - u[n-1], with u[-1] moved to d0
  for (int n = 0; n < kN; ++n) {
    D(n, n) = 1.0;
    if (n > 0) D(n, n - 1) = -1.0;
  }
  Eigen::VectorXd d0 = Eigen::VectorXd::Zero(kN);
  d0(0) = u_prev;
  const Eigen::MatrixXd H =
      50.0 * Phi.transpose() * Phi + 0.1 * Eigen::MatrixXd::Identity(kN, kN) + w_delta * D.transpose() * D;
  const Eigen::VectorXd g =
      50.0 * Phi.transpose() * (Eigen::VectorXd::Ones(kN + 1) - free_response) + w_delta * D.transpose() * d0;
  const Eigen::VectorXd u_ref = H.ldlt().solve(g);
  for (int n = 0; n < kN; ++n) EXPECT_NEAR(u(n, 0), u_ref(n), 1e-9) << "step " << n;
  // The carried-input outputs are u[n-1].
  for (int n = 1; n <= kN; ++n) EXPECT_NEAR(plan.outputs(n, 1), u(n - 1, 0), 1e-12);
  EXPECT_NEAR(plan.outputs(0, 1), u_prev, 1e-15);
}

TEST(InputDifferences, RateLimitsAndInputBoxesHoldTogether) {
  Problem p = SmallPlant();
  for (int n = 0; n < kN; ++n) p.mutable_input_prior(n, 0) = ScalarPrior::Box(-0.5, 0.5).WithGaussian(0.0, 10.0);
  const double rate = 0.05;
  auto augmented = AugmentWithInputDifferences(
      p, std::vector<ScalarPrior>(kN, ScalarPrior::Box(-rate, rate).WithGaussian(0.0, 1.0)), Eigen::VectorXd::Zero(1));
  ASSERT_TRUE(augmented.ok()) << augmented.status();
  auto session = Session::Create(*augmented);
  ASSERT_TRUE(session.ok()) << session.status();
  Solution plan;
  auto summary = (*session)->Solve(&plan);
  ASSERT_TRUE(summary.ok());
  EXPECT_EQ(summary->status, SolveStatus::kConverged) << summary->Describe();
  const Eigen::MatrixXd u = InputsFromDifferences(plan.inputs, Eigen::VectorXd::Zero(1));
  for (int n = 0; n < kN; ++n) {
    EXPECT_LE(std::abs(plan.inputs(n, 0)), rate + 1e-9) << "step " << n;
    EXPECT_LE(std::abs(u(n, 0)), 0.5 + 1e-9) << "step " << n;
  }
  // The limit binds: the plan wants to move faster at the start (move-suppression weight 1).
  EXPECT_NEAR(plan.inputs(0, 0), rate, 1e-9);
}

TEST(InputDifferences, BadArgumentsNameTheField) {
  const Problem p = SmallPlant();
  EXPECT_THAT(AugmentWithInputDifferences(p, std::vector<ScalarPrior>(3), Eigen::VectorXd::Zero(1)).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("delta_priors")));
  EXPECT_THAT(AugmentWithInputDifferences(p, std::vector<ScalarPrior>(kN), Eigen::VectorXd::Zero(2)).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("previous_input")));
  std::vector<ScalarPrior> bad(kN);
  bad[4] = ScalarPrior::Box(1.0, -1.0);
  EXPECT_THAT(AugmentWithInputDifferences(p, bad, Eigen::VectorXd::Zero(1)).status(),
              testing::StatusIs(absl::StatusCode::kInvalidArgument, ::testing::HasSubstr("delta_priors[4]")));
}

}  // namespace
}  // namespace nupmpc::core
