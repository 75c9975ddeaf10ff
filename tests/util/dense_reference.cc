#include "tests/util/dense_reference.h"

#include <vector>

#include "Eigen/Dense"

namespace nupmpc::testing {

DensePosterior SolveDense(const core::Problem& p) {
  const int M = p.num_states, L = p.num_inputs, K = p.num_outputs, N = p.horizon;
  const bool free_x0 = !p.initial_state_fixed();
  const int nz = (free_x0 ? M : 0) + N * L;
  const int u_off = free_x0 ? M : 0;
  // x[n] = Phi[n] z + r[n]  (affine in the decision vector)
  std::vector<Eigen::MatrixXd> Phi(N + 1, Eigen::MatrixXd::Zero(M, nz));
  std::vector<Eigen::VectorXd> r(N + 1, Eigen::VectorXd::Zero(M));
  if (free_x0) {
    Phi[0].leftCols(M).setIdentity();
  } else {
    r[0] = p.initial_mean;
  }
  for (int n = 0; n < N; ++n) {
    Phi[n + 1] = p.A_at(n) * Phi[n];
    Phi[n + 1].middleCols(u_off + n * L, L) += p.B_at(n);
    r[n + 1] = p.A_at(n) * r[n];
    for (int i = 0; i < M; ++i) r[n + 1](i) += p.state_offset_at(n, i);
  }
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(nz, nz);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(nz);
  const auto add = [&](const Eigen::VectorXd& a, double offset, double mean, double var) {
    H += a * a.transpose() / var;
    b += a * (mean - offset) / var;
  };
  if (free_x0) {
    const Eigen::MatrixXd W0 = p.initial_covariance.inverse();
    H.topLeftCorner(M, M) += W0;
    b.head(M) += W0 * p.initial_mean;
  }
  for (int n = 0; n < N; ++n) {
    for (int l = 0; l < L; ++l) {
      const core::ScalarPrior& prior = p.input_prior(n, l);
      if (!prior.has_gaussian()) continue;
      Eigen::VectorXd a = Eigen::VectorXd::Zero(nz);
      a(u_off + n * L + l) = 1.0;
      add(a, 0.0, prior.mean, prior.variance);
    }
  }
  for (int n = 0; n <= N; ++n) {
    for (int k = 0; k < K; ++k) {
      const core::ScalarPrior& prior = p.output_prior(n, k);
      if (!prior.has_gaussian()) continue;
      const Eigen::VectorXd c = p.C_at(n).row(k).transpose();
      add(Phi[n].transpose() * c, c.dot(r[n]) + p.output_offset_at(n, k), prior.mean, prior.variance);
    }
  }
  if (p.terminal.has_value()) {
    const Eigen::MatrixXd& Qf = p.terminal->weight;
    H += Phi[N].transpose() * Qf * Phi[N];
    b += Phi[N].transpose() * Qf * (p.terminal->target - r[N]);
  }
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(H);
  const Eigen::VectorXd z = ldlt.solve(b);
  const Eigen::MatrixXd cov = ldlt.solve(Eigen::MatrixXd::Identity(nz, nz));

  DensePosterior out;
  out.x0_mean = free_x0 ? Eigen::VectorXd(z.head(M)) : p.initial_mean;
  out.x0_cov = free_x0 ? Eigen::MatrixXd(cov.topLeftCorner(M, M)) : Eigen::MatrixXd::Zero(M, M);
  out.u_mean.resize(L, N);
  out.u_var.resize(L, N);
  for (int n = 0; n < N; ++n) {
    for (int l = 0; l < L; ++l) {
      out.u_mean(l, n) = z(u_off + n * L + l);
      out.u_var(l, n) = cov(u_off + n * L + l, u_off + n * L + l);
    }
  }
  out.y_mean.resize(K, N + 1);
  out.y_var.resize(K, N + 1);
  for (int n = 0; n <= N; ++n) {
    for (int k = 0; k < K; ++k) {
      const Eigen::VectorXd a = Phi[n].transpose() * p.C_at(n).row(k).transpose();
      out.y_mean(k, n) = a.dot(z) + p.C_at(n).row(k).dot(r[n]) + p.output_offset_at(n, k);
      out.y_var(k, n) = a.dot(cov * a);
    }
  }
  return out;
}

}  // namespace nupmpc::testing
