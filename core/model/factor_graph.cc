#include "core/model/factor_graph.h"

#include <map>
#include <tuple>

#include "Eigen/Eigenvalues"
#include "core/message_passing/fixed_size.h"

namespace nupmpc::core {
namespace {

bool HasTerminal(const Problem& p) { return p.terminal.has_value(); }

// Pool row of output k at step n.
int OutputPoolRow(const Problem& p, int n, int k) { return p.C.size() == 1 ? k : n * p.num_outputs + k; }
int NumOutputPoolRows(const Problem& p) { return p.C.size() == 1 ? p.num_outputs : (p.horizon + 1) * p.num_outputs; }

ScalarPrior GaussianPartOnly(const ScalarPrior& p) {
  return p.has_gaussian() ? ScalarPrior::Gaussian(p.mean, p.variance) : ScalarPrior::Free();
}
ScalarPrior KindPartOnly(const ScalarPrior& p) {
  ScalarPrior q = p;
  q.mean = 0.0;
  q.variance = kInfinity;
  return q;
}

}  // namespace

FactorGraph BuildFactorGraph(const Problem& p, bool augment_inputs) {
  FactorGraph g;
  const int M0 = p.num_states, L = p.num_inputs, K = p.num_outputs, N = p.horizon;
  g.base_M = M0;
  g.augmented = augment_inputs && L > 0;
  g.M = g.augmented ? PaddedStateSize(M0 + L) : M0;
  g.L = L;
  g.N = N;
  g.A_pool.assign(p.A.size(), Eigen::MatrixXd::Zero(g.M, g.M));
  g.B_pool.assign(p.B.size(), Eigen::MatrixXd::Zero(g.M, L));
  g.a_of.resize(N);
  g.b_of.resize(N);
  for (int n = 0; n < N; ++n) {
    g.a_of[n] = p.A.size() == 1 ? 0 : n;
    g.b_of[n] = p.B.size() == 1 ? 0 : n;
  }
  g.cx = Eigen::MatrixXd::Zero(g.M, N);

  const int aug_pool_begin = NumOutputPoolRows(p);
  const int terminal_pool_begin = aug_pool_begin + (g.augmented ? L : 0);
  g.c_pool = RowMajorMatrix::Zero(terminal_pool_begin + (HasTerminal(p) ? M0 : 0), g.M);

  g.row_begin.assign(N + 2, 0);
  for (int n = 0; n <= N; ++n) {
    g.row_begin[n] = g.num_rows();
    for (int k = 0; k < K; ++k) {
      g.row_c.push_back(OutputPoolRow(p, n, k));
      g.row_origin.push_back({RowOrigin::Type::kOutput, n, k});
    }
    if (g.augmented && n >= 1) {
      for (int l = 0; l < L; ++l) {
        g.row_c.push_back(aug_pool_begin + l);
        g.row_origin.push_back({RowOrigin::Type::kInput, n - 1, l});
      }
    }
    if (n == N && HasTerminal(p)) {
      for (int i = 0; i < M0; ++i) {
        g.row_c.push_back(terminal_pool_begin + i);
        g.row_origin.push_back({RowOrigin::Type::kTerminal, N, i});
      }
    }
  }
  g.row_begin[N + 1] = g.num_rows();
  g.row_d.assign(g.num_rows(), 0.0);
  g.row_prior.assign(g.num_rows(), ScalarPrior::Free());
  g.input_prior.assign(static_cast<std::size_t>(N) * L, ScalarPrior::Free());
  g.m0 = Eigen::VectorXd::Zero(g.M);
  g.V0 = Eigen::MatrixXd::Zero(g.M, g.M);

  // Warm-start shift map: row (type, step, index) takes the state of (type, step+1, index).
  std::map<std::tuple<int, int, int>, int> by_origin;
  for (int r = 0; r < g.num_rows(); ++r) {
    const RowOrigin& o = g.row_origin[r];
    by_origin[{static_cast<int>(o.type), o.step, o.index}] = r;
  }
  g.row_shift_source.resize(g.num_rows());
  for (int r = 0; r < g.num_rows(); ++r) {
    const RowOrigin& o = g.row_origin[r];
    auto it = by_origin.find({static_cast<int>(o.type), o.step + 1, o.index});
    g.row_shift_source[r] = it == by_origin.end() ? r : it->second;
  }

  RefreshFactorGraph(p, &g);
  return g;
}

void RefreshFactorGraph(const Problem& p, FactorGraph* graph) {
  FactorGraph& g = *graph;
  const int M0 = p.num_states, L = p.num_inputs, K = p.num_outputs, N = p.horizon;
  for (std::size_t i = 0; i < p.A.size(); ++i) g.A_pool[i].topLeftCorner(M0, M0) = p.A[i];
  for (std::size_t i = 0; i < p.B.size(); ++i) {
    g.B_pool[i].topRows(M0) = p.B[i];
    if (g.augmented) g.B_pool[i].middleRows(M0, L).setIdentity();
  }
  for (int n = 0; n < N; ++n) {
    for (int i = 0; i < M0; ++i) g.cx(i, n) = p.state_offset_at(n, i);
  }
  const int num_output_pool_rows = NumOutputPoolRows(p);
  for (int r = 0; r < num_output_pool_rows; ++r) {
    const Eigen::MatrixXd& C = p.C.size() == 1 ? p.C[0] : p.C[r / K];
    g.c_pool.row(r).head(M0) = C.row(p.C.size() == 1 ? r : r % K);
  }
  if (g.augmented) {
    for (int l = 0; l < L; ++l) g.c_pool(num_output_pool_rows + l, M0 + l) = 1.0;
  }

  // Terminal cost ½(x-x_f)ᵀQf(x-x_f) = Σ_i ½ (√λ_i q_iᵀx - √λ_i q_iᵀx_f)² (§2): rows with
  // unit-variance Gaussians; rows of zero eigenvalues carry no factor.
  Eigen::VectorXd terminal_mean;
  Eigen::VectorXd terminal_scale;
  if (p.terminal.has_value()) {
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(p.terminal->weight);
    const int first = num_output_pool_rows + (g.augmented ? L : 0);
    const double lmax = std::max(eig.eigenvalues().cwiseAbs().maxCoeff(), 1e-300);
    terminal_mean.resize(M0);
    terminal_scale.resize(M0);
    for (int i = 0; i < M0; ++i) {
      const double lambda = eig.eigenvalues()(i);
      terminal_scale(i) = lambda > 1e-14 * lmax ? std::sqrt(lambda) : 0.0;
      g.c_pool.row(first + i).head(M0) = terminal_scale(i) * eig.eigenvectors().col(i).transpose();
      terminal_mean(i) = g.c_pool.row(first + i).head(M0).dot(p.terminal->target);
    }
  }

  g.row_unit.resize(g.num_rows());
  for (int r = 0; r < g.num_rows(); ++r) {
    const auto c = g.c(r);
    Eigen::Index i = 0;
    const bool unit = c.cwiseAbs().maxCoeff(&i) == 1.0 && c(i) == 1.0 && c.cwiseAbs().sum() == 1.0;
    g.row_unit[r] = unit ? static_cast<int>(i) : -1;
  }
  for (int r = 0; r < g.num_rows(); ++r) {
    const RowOrigin& o = g.row_origin[r];
    switch (o.type) {
      case RowOrigin::Type::kOutput:
        g.row_d[r] = p.output_offset_at(o.step, o.index);
        g.row_prior[r] = p.output_prior(o.step, o.index);
        break;
      case RowOrigin::Type::kInput:
        g.row_d[r] = 0.0;
        g.row_prior[r] = KindPartOnly(p.input_prior(o.step, o.index));
        break;
      case RowOrigin::Type::kTerminal:
        g.row_d[r] = 0.0;
        g.row_prior[r] =
            terminal_scale(o.index) > 0.0 ? ScalarPrior::Gaussian(terminal_mean(o.index), 1.0) : ScalarPrior::Free();
        break;
    }
  }
  for (int n = 0; n < N; ++n) {
    for (int l = 0; l < L; ++l) {
      const ScalarPrior& prior = p.input_prior(n, l);
      g.input_prior[n * L + l] = g.augmented ? GaussianPartOnly(prior) : prior;
    }
  }
  g.m0.head(M0) = p.initial_mean;
  g.x0_fixed = p.initial_state_fixed();
  if (g.x0_fixed) {
    g.V0.setZero();
  } else {
    g.V0.topLeftCorner(M0, M0) = p.initial_covariance;
  }
}

void RefreshFactorGraphOutputPriors(const Problem& p, FactorGraph* graph) {
  for (int r = 0; r < graph->num_rows(); ++r) {
    const RowOrigin& o = graph->row_origin[r];
    if (o.type == RowOrigin::Type::kOutput) graph->row_prior[r] = p.output_prior(o.step, o.index);
  }
}

}  // namespace nupmpc::core
