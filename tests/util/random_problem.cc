#include "tests/util/random_problem.h"

#include "Eigen/Eigenvalues"

namespace nupmpc::testing {

core::Problem RandomGaussianProblem(const RandomProblemSpec& spec) {
  std::mt19937 rng(spec.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.2, 2.0);
  const auto random_matrix = [&](int r, int c) {
    Eigen::MatrixXd m(r, c);
    for (int i = 0; i < r; ++i)
      for (int j = 0; j < c; ++j) m(i, j) = normal(rng);
    return m;
  };
  const int M = spec.M, L = spec.L, K = spec.K, N = spec.N;
  core::Problem p = core::Problem::TimeInvariant(M, L, K, N);
  const int steps = spec.time_varying ? N : 1;
  p.A.clear();
  p.B.clear();
  p.C.clear();
  for (int n = 0; n < steps; ++n) {
    Eigen::MatrixXd A = random_matrix(M, M);
    const double rho = A.eigenvalues().cwiseAbs().maxCoeff();
    p.A.push_back(0.9 * A / rho);
    p.B.push_back(random_matrix(M, L));
  }
  for (int n = 0; n < (spec.time_varying ? N + 1 : 1); ++n) p.C.push_back(random_matrix(K, M));
  if (spec.offsets) {
    for (int n = 0; n < N; ++n) p.state_offset.push_back(0.3 * random_matrix(M, 1).col(0));
    for (int n = 0; n <= N; ++n) p.output_offset.push_back(0.3 * random_matrix(K, 1).col(0));
  }
  p.initial_mean = random_matrix(M, 1).col(0);
  if (spec.free_x0) {
    const Eigen::MatrixXd S = random_matrix(M, M);
    p.initial_covariance = 0.5 * S * S.transpose() + 0.1 * Eigen::MatrixXd::Identity(M, M);
  }
  for (int n = 0; n < N; ++n)
    for (int l = 0; l < L; ++l) p.mutable_input_prior(n, l) = core::ScalarPrior::Gaussian(normal(rng), uniform(rng));
  for (int n = 0; n <= N; ++n) {
    for (int k = 0; k < K; ++k) {
      // Every fourth output is free (no factor), the rest are Gaussian references.
      p.mutable_output_prior(n, k) =
          (n + k) % 4 == 3 ? core::ScalarPrior::Free() : core::ScalarPrior::Gaussian(normal(rng), uniform(rng));
    }
  }
  if (spec.terminal) {
    const Eigen::MatrixXd S = random_matrix(M, M);
    p.terminal = core::Problem::Terminal{random_matrix(M, 1).col(0), S * S.transpose()};
  }
  return p;
}

core::Problem WithBoxes(core::Problem p, double input_bound, double output_bound) {
  if (input_bound > 0.0) {
    for (core::ScalarPrior& prior : p.input_priors) {
      prior = core::ScalarPrior::Box(-input_bound, input_bound).WithGaussian(prior.mean, prior.variance);
    }
  }
  if (output_bound > 0.0) {
    for (core::ScalarPrior& prior : p.output_priors) {
      if (prior.has_gaussian()) {
        prior = core::ScalarPrior::Box(-output_bound, output_bound).WithGaussian(prior.mean, prior.variance);
      }
    }
  }
  return p;
}

}  // namespace nupmpc::testing
