#include "loadtest/bench/random_output_box.h"

#include <cmath>
#include <random>

namespace nupmpc::bench {

core::Problem MakeRandomOutputBox(int M, int K, int L, int N, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-0.1, 0.1);
  const double matrix_sd = std::sqrt(1.0 / 1000.0);
  const auto draw = [&](int rows, int cols, double sd) {
    Eigen::MatrixXd m(rows, cols);
    for (int i = 0; i < rows; ++i) {
      for (int j = 0; j < cols; ++j) m(i, j) = sd * normal(rng);
    }
    return m;
  };
  core::Problem p;
  p.num_states = M;
  p.num_inputs = L;
  p.num_outputs = K;
  p.horizon = N;
  p.A = {draw(M, M, matrix_sd)};
  p.B = {draw(M, L, matrix_sd)};
  p.C = {draw(K, M, matrix_sd)};
  p.initial_mean = Eigen::VectorXd::Zero(M);
  p.initial_covariance = Eigen::MatrixXd::Identity(M, M) / M;
  p.input_priors.assign(static_cast<std::size_t>(N) * L, core::ScalarPrior::Gaussian(0.0, 1.0 / L));
  p.output_priors.assign(static_cast<std::size_t>(N + 1) * K, core::ScalarPrior::Free());
  Eigen::VectorXd x = draw(M, 1, std::sqrt(1.0 / M));
  for (int n = 0; n < N; ++n) {
    const Eigen::VectorXd y = p.C[0] * x;
    for (int k = 0; k < K; ++k) {
      const double centre = y(k) * (1.0 + uniform(rng));
      const double half_width = 0.1 * std::abs(centre);
      p.mutable_output_prior(n, k) = core::ScalarPrior::Box(centre - half_width, centre + half_width);
    }
    x = p.A[0] * x + p.B[0] * draw(L, 1, std::sqrt(1.0 / L));
  }
  return p;
}

}  // namespace nupmpc::bench
