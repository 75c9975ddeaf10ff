#include "core/message_passing/forward_filter.h"

#include <algorithm>

#include "core/util/symmetrize.h"

namespace nupmpc::core {

void ForwardFilterWorkspace::Resize(const FactorGraph& graph, bool keep_edges) {
  const int M = graph.M, R = graph.num_rows(), N = graph.N, L = graph.L;
  v.setZero(M, R);
  s.setZero(R);
  yhat.setZero(R);
  G.setZero(R);
  g.setZero(R);
  if (keep_edges) {
    m_post.setZero(M, N + 1);
    V_post.setZero(M, M * (N + 1));
  }
  mU.setZero(L, N);
  VU.setZero(L, N);
  m.setZero(M);
  V.setZero(M, M);
  AV.setZero(M, M);
  BD.setZero(M, L);
}

void LoadInputMoments(const FactorGraph& graph, const ScalarFactor* input_factor,
                      ForwardFilterWorkspace* ws) {
  for (int n = 0; n < graph.N; ++n) {
    for (int l = 0; l < graph.L; ++l) {
      const MomentForm mf = ToMoment(input_factor[n * graph.L + l]);
      ws->mU(l, n) = mf.mean;
      ws->VU(l, n) = mf.variance;  // callers guarantee mf.ok (Gaussian inputs)
    }
  }
}

void RunForwardFilter(const FactorGraph& graph, const ScalarFactor* input_factor,
                      const ScalarFactor* row_factor, bool keep_edges, ForwardFilterWorkspace* ws) {
  if (input_factor != nullptr) LoadInputMoments(graph, input_factor, ws);
  const int M = graph.M, N = graph.N;
  Eigen::VectorXd& m = ws->m;
  Eigen::MatrixXd& V = ws->V;
  m = graph.m0;
  V = graph.V0;
  for (int n = 0; n <= N; ++n) {
    // A pinned factor on a row whose prior variance is (numerically) zero carries no
    // information and would divide by ~0: skip it relative to the state's variance scale.
    const double variance_scale = std::max(V.diagonal().maxCoeff(), 0.0);
    for (int r = graph.row_begin[n]; r < graph.row_begin[n + 1]; ++r) {
      const ScalarFactor& f = row_factor[r];
      if (f.empty()) {
        ws->G(r) = ws->g(r) = 0.0;
        // IFFBDD needs v, s, ŷ of every constrained row even when its factor is empty.
        if (graph.row_prior[r].kind == PriorKind::kNone) continue;
      }
      const auto c = graph.c(r);
      auto v = ws->v.col(r);
      v.noalias() = V * c;
      const double s = c.dot(v);
      const double yhat = c.dot(m) + graph.row_d[r];
      ws->s(r) = s;
      ws->yhat(r) = yhat;
      if (f.empty()) continue;
      double G, g;
      if (f.V == kInfinity) {  // canonical (ξ, w); w = 0 is a pure linear factor
        const double den = 1.0 + f.w * s;
        G = f.w / den;
        g = (f.xi - f.w * yhat) / den;
      } else {
        const MomentForm mf = ToMoment(f);
        const double den = mf.variance + s;
        if (den <= 1e-13 * c.squaredNorm() * variance_scale) {
          // Degenerate: the output is already determined. s = 0 tells the backward
          // passes that this row has no extrinsic variance (§12.2).
          ws->G(r) = ws->g(r) = ws->s(r) = 0.0;
          continue;
        }
        G = 1.0 / den;
        g = (mf.mean - yhat) / den;
      }
      ws->G(r) = G;
      ws->g(r) = g;
      m.noalias() += g * v;
      V.noalias() -= G * v * v.transpose();
    }
    SymmetrizeInPlace(V);
    if (keep_edges) {
      ws->m_post.col(n) = m;
      ws->V_post.middleCols(n * M, M) = V;
    }
    if (n == N) break;
    const auto& A = graph.A(n);
    const auto& B = graph.B(n);
    // m ← A m + B mU + cx;  V ← A V Aᵀ + B diag(VU) Bᵀ
    ws->AV.col(0).noalias() = A * m;  // reuse AV's first column as scratch for the mean
    m.noalias() = ws->AV.col(0);
    m.noalias() += B * ws->mU.col(n);
    m += graph.cx.col(n);
    ws->AV.noalias() = A * V;
    V.noalias() = ws->AV * A.transpose();
    ws->BD.noalias() = B * ws->VU.col(n).asDiagonal();
    V.noalias() += ws->BD * B.transpose();
  }
}

}  // namespace nupmpc::core
