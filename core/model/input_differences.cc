#include "core/model/input_differences.h"

#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {

absl::StatusOr<Problem> AugmentWithInputDifferences(const Problem& p, const std::vector<ScalarPrior>& delta_priors,
                                                    const Eigen::VectorXd& previous_input) {
  NUPMPC_RETURN_IF_ERROR(Validate(p));
  const int M = p.num_states, L = p.num_inputs, K = p.num_outputs, N = p.horizon;
  if (delta_priors.size() != static_cast<std::size_t>(N) * L) {
    return absl::InvalidArgumentError(
        absl::StrCat("delta_priors: expected N·L = ", N * L, " priors, got ", delta_priors.size()));
  }
  if (previous_input.size() != L) {
    return absl::InvalidArgumentError(
        absl::StrCat("previous_input: expected ", L, " values (num_inputs), got ", previous_input.size()));
  }
  if (!previous_input.allFinite()) return absl::InvalidArgumentError("previous_input: must be finite");
  if (!p.initial_state_fixed()) {
    // u[-1] would be a zero-variance block of a Gaussian x'[0], which the initial-state
    // solve cannot factor.
    return absl::FailedPreconditionError("initial_covariance: input differences need a fixed (measured) initial state");
  }
  for (std::size_t i = 0; i < delta_priors.size(); ++i) {
    NUPMPC_RETURN_IF_ERROR(ValidatePrior(delta_priors[i], "delta_priors", static_cast<int>(i)));
  }

  Problem a;
  a.num_states = M + L;
  a.num_inputs = L;
  a.num_outputs = K + L;
  a.horizon = N;
  // A' holds B: one A' per step as soon as A or B varies.
  const int model_steps = (p.A.size() == 1 && p.B.size() == 1) ? 1 : N;
  for (int n = 0; n < model_steps; ++n) {
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(M + L, M + L);
    A.topLeftCorner(M, M) = p.A_at(n);
    A.topRightCorner(M, L) = p.B_at(n);
    A.bottomRightCorner(L, L).setIdentity();
    Eigen::MatrixXd B(M + L, L);
    B.topRows(M) = p.B_at(n);
    B.bottomRows(L).setIdentity();
    a.A.push_back(std::move(A));
    a.B.push_back(std::move(B));
  }
  for (std::size_t n = 0; n < p.C.size(); ++n) {
    Eigen::MatrixXd C = Eigen::MatrixXd::Zero(K + L, M + L);
    C.topLeftCorner(K, M) = p.C[n];
    C.bottomRightCorner(L, L).setIdentity();
    a.C.push_back(std::move(C));
  }
  for (const Eigen::VectorXd& c : p.state_offset) {
    Eigen::VectorXd ca = Eigen::VectorXd::Zero(M + L);
    ca.head(M) = c;
    a.state_offset.push_back(std::move(ca));
  }
  for (const Eigen::VectorXd& d : p.output_offset) {
    Eigen::VectorXd da = Eigen::VectorXd::Zero(K + L);
    da.head(K) = d;
    a.output_offset.push_back(std::move(da));
  }
  a.initial_mean.resize(M + L);
  a.initial_mean << p.initial_mean, previous_input;
  a.input_priors = delta_priors;
  a.output_priors.assign(static_cast<std::size_t>(N + 1) * (K + L), ScalarPrior::Free());
  for (int n = 0; n <= N; ++n) {
    for (int k = 0; k < K; ++k) a.mutable_output_prior(n, k) = p.output_prior(n, k);
    if (n == 0) continue;  // output K + l at step 0 is u[-1]: given, no prior
    for (int l = 0; l < L; ++l) a.mutable_output_prior(n, K + l) = p.input_prior(n - 1, l);
  }
  if (p.terminal.has_value()) {
    Problem::Terminal t;
    t.target = Eigen::VectorXd::Zero(M + L);
    t.target.head(M) = p.terminal->target;
    t.weight = Eigen::MatrixXd::Zero(M + L, M + L);
    t.weight.topLeftCorner(M, M) = p.terminal->weight;
    a.terminal = std::move(t);
  }
  return a;
}

Eigen::MatrixXd InputsFromDifferences(const Eigen::MatrixXd& differences, const Eigen::VectorXd& previous_input) {
  Eigen::MatrixXd u(differences.rows(), differences.cols());
  Eigen::VectorXd running = previous_input;
  for (Eigen::Index n = 0; n < differences.rows(); ++n) {
    running += differences.row(n).transpose();
    u.row(n) = running.transpose();
  }
  return u;
}

}  // namespace nupmpc::core
