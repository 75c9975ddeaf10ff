#include "core/message_passing/smoother.h"

#include "core/util/symmetrize.h"

namespace nupmpc::core {

void SmootherWorkspace::Resize(const FactorGraph& g) {
  mU.setZero(g.L, g.N);
  VU.setZero(g.L, g.N);
  mY.setZero(g.num_rows());
  VY.setZero(g.num_rows());
  mX0.setZero(g.M);
  VX0.setZero(g.M, g.M);
  xi.setZero(g.M);
  mX.setZero(g.M);
  z.setZero(g.M);
  Btxi.setZero(g.L);
  W.setZero(g.M, g.M);
  VX.setZero(g.M, g.M);
  WV.setZero(g.M, g.M);
  AtW.setZero(g.M, g.M);
}

void RunSmootherBackward(const FactorGraph& g, const ForwardFilterWorkspace& fw, bool with_variances,
                         SmootherWorkspace* ws, Interrupt* interrupt) {
  const int M = g.M, N = g.N;
  StopPoll stop(interrupt);
  Eigen::VectorXd& xi = ws->xi;  // ξ̃ = W̃ (m_fwd - m_bwd)
  Eigen::MatrixXd& W = ws->W;    // W̃ = (V_fwd + V_bwd)⁻¹
  xi.setZero();
  W.setZero();
  for (int n = N; n >= 0; --n) {
    if (stop()) return;
    const auto m_post = fw.m_post.col(n);
    const auto V_post = fw.V_post.middleCols(n * M, M);
    ws->mX.noalias() = m_post;
    ws->mX.noalias() -= V_post * xi;
    if (with_variances) {
      ws->WV.noalias() = W * V_post;
      ws->VX.noalias() = V_post;
      ws->VX.noalias() -= V_post * ws->WV;
    }
    for (int r = g.row_begin[n]; r < g.row_begin[n + 1]; ++r) {
      const auto c = g.c(r);
      ws->mY(r) = c.dot(ws->mX) + g.row_d[r];
      if (with_variances) {
        ws->z.noalias() = ws->VX * c;
        ws->VY(r) = c.dot(ws->z);
      }
    }
    // Undo the row updates of step n in reverse order (ξ̃_pre = Fᵀξ̃ - c g,
    // W̃_pre = Fᵀ W̃ F + G c cᵀ with F = I - v G cᵀ, expanded to O(M²)).
    for (int r = g.row_begin[n + 1] - 1; r >= g.row_begin[n]; --r) {
      const double G = fw.G(r), gg = fw.g(r);
      if (G == 0.0 && gg == 0.0) continue;
      const auto c = g.c(r);
      const auto v = fw.v.col(r);
      const double t = v.dot(xi);
      if (with_variances) {
        ws->z.noalias() = W * v;
        const double q = v.dot(ws->z);
        W.noalias() -= G * (c * ws->z.transpose());
        W.noalias() -= G * (ws->z * c.transpose());
        W.noalias() += (G * G * q + G) * (c * c.transpose());
      }
      xi.noalias() -= (G * t + gg) * c;
    }
    if (n == 0) break;
    const int j = n - 1;
    const auto& A = g.A(j);
    const auto& B = g.B(j);
    ws->Btxi.noalias() = B.transpose() * xi;
    for (int l = 0; l < g.L; ++l) {
      const double VUl = fw.VU(l, j);
      ws->mU(l, j) = fw.mU(l, j) - VUl * ws->Btxi(l);
      if (with_variances) {
        const auto b = B.col(l);
        ws->z.noalias() = W * b;
        ws->VU(l, j) = VUl - VUl * VUl * b.dot(ws->z);
      }
    }
    ws->z.noalias() = A.transpose() * xi;
    xi = ws->z;
    if (with_variances) {
      ws->AtW.noalias() = A.transpose() * W;
      W.noalias() = ws->AtW * A;
      SymmetrizeInPlace(W);
    }
  }
  ws->mX0.noalias() = g.m0;
  ws->mX0.noalias() -= g.V0 * xi;
  if (with_variances) {
    ws->WV.noalias() = W * g.V0;
    ws->VX0.noalias() = g.V0;
    ws->VX0.noalias() -= g.V0 * ws->WV;
  }
}

}  // namespace nupmpc::core
