#include "core/message_passing/forward_filter.h"

#include <algorithm>

#include "core/message_passing/fixed_size.h"
#include "core/util/prefetch.h"
#include "core/util/symmetrize.h"

namespace nupmpc::core {
namespace {

// Scratch of the filter: stack objects for a fixed size, the workspace's for Dynamic.
template <int MS>
struct FilterScratch {
  explicit FilterScratch(ForwardFilterWorkspace*) {}
  StateMatrix<MS> V, AV;
  StateVector<MS> m, t;
};
template <>
struct FilterScratch<Eigen::Dynamic> {
  explicit FilterScratch(ForwardFilterWorkspace* ws) : V(ws->V), AV(ws->AV), m(ws->m), t(ws->t) {}
  Eigen::MatrixXd& V;
  Eigen::MatrixXd& AV;
  Eigen::VectorXd& m;
  Eigen::VectorXd& t;
};

// `factor_of(r, yhat, s, v)` gives the factor of a row with a constraint kind once its
// prediction is known; rows of kind kNone use row_factor[r].
template <int MS, typename FactorOf>
void Filter(const FactorGraph& graph, const ScalarFactor* row_factor, FactorOf&& factor_of, bool keep_edges,
            ForwardFilterWorkspace* ws, Interrupt* interrupt) {
  const int M = graph.M, N = graph.N, L = graph.L;
  FilterScratch<MS> s(ws);
  StopPoll stop(interrupt);
  auto& V = s.V;
  auto& m = s.m;
  V = ConstView<MS, MS>(graph.V0.data(), M, M);
  m = ConstView<MS, 1>(graph.m0.data(), M, 1);
  for (int n = 0; n <= N; ++n) {
    if (stop()) return;
    // A pinned factor on a row whose prior variance is (numerically) zero carries no
    // information and would divide by ~0: skip it relative to the state's variance scale.
    const double variance_scale = std::max(V.diagonal().maxCoeff(), 0.0);
    for (int r = graph.row_begin[n]; r < graph.row_begin[n + 1]; ++r) {
      const bool constrained = graph.row_prior[r].kind != PriorKind::kNone;
      // IFFBDD needs v, s, ŷ of every constrained row even when its factor is empty.
      if (!constrained && row_factor[r].empty()) {
        ws->G(r) = ws->g(r) = 0.0;
        continue;
      }
      if (r + kPrefetchRows < ws->v.cols()) PrefetchForWrite(ws->v.col(r + kPrefetchRows).data(), M);
      const auto c = ConstView<MS, 1>(graph.c_pool.data() + static_cast<Eigen::Index>(graph.row_c[r]) * M, M, 1);
      Eigen::Map<StateVector<MS>> v(ws->v.col(r).data(), M);
      const int unit = graph.row_unit[r];  // c = e_unit: no product needed (C = I, augmented inputs)
      double sr, yhat;
      if (unit >= 0) {
        v = V.col(unit);
        sr = v(unit);
        yhat = m(unit) + graph.row_d[r];
      } else {
        StateProduct<MS>(v, V, c);
        sr = c.dot(v);
        yhat = c.dot(m) + graph.row_d[r];
      }
      ws->s(r) = sr;
      ws->yhat(r) = yhat;
      const ScalarFactor f = constrained ? factor_of(r, yhat, sr, v.data()) : row_factor[r];
      if (f.empty()) {
        ws->G(r) = ws->g(r) = 0.0;
        continue;
      }
      double G, g;
      if (f.V == kInfinity) {  // canonical (ξ, w); w = 0 is a pure linear factor
        const double den = 1.0 + f.w * sr;
        G = f.w / den;
        g = (f.xi - f.w * yhat) / den;
      } else {
        const MomentForm mf = ToMoment(f);
        const double den = mf.variance + sr;
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
    const auto A = ConstView<MS, MS>(graph.A(n).data(), M, M);
    const auto B = ConstView<MS, Eigen::Dynamic>(graph.B(n).data(), M, L);
    // m ← A m + B mU + cx;  V ← A V Aᵀ + B diag(VU) Bᵀ
    StateProduct<MS>(s.t, A, m);
    m.noalias() = s.t;
    m.noalias() += B * ws->mU.col(n);
    m += ConstView<MS, 1>(graph.cx.col(n).data(), M, 1);
    if (MS == Eigen::Dynamic && graph.augmented) {
      // A' = [[A, 0], [0, 0]] (§9.6): only the top-left block of A' V A'ᵀ is nonzero. (Fixed
      // sizes multiply whole: a runtime-sized block would leave the unrolled kernel.)
      const int M0 = graph.base_M;
      s.AV.topLeftCorner(M0, M0).noalias() = A.topLeftCorner(M0, M0) * V.topLeftCorner(M0, M0);
      V.topLeftCorner(M0, M0).noalias() = s.AV.topLeftCorner(M0, M0) * A.topLeftCorner(M0, M0).transpose();
      V.rightCols(M - M0).setZero();
      V.bottomLeftCorner(M - M0, M0).setZero();
    } else {
      StateProduct<MS>(s.AV, A, V);
      StateProduct<MS>(V, s.AV, A.transpose());
    }
    if constexpr (MS == Eigen::Dynamic) {
      ws->BD.noalias() = B * ws->VU.col(n).asDiagonal();  // large M: one GEMM beats L rank-1 updates
      V.noalias() += ws->BD * B.transpose();
    } else {
      for (int l = 0; l < L; ++l) V.noalias() += ws->VU(l, n) * (B.col(l) * B.col(l).transpose());
    }
  }
}

template <int MS>
void Means(const FactorGraph& graph, const ScalarFactor* row_factor, ForwardFilterWorkspace* ws, Interrupt* interrupt) {
  const int M = graph.M, N = graph.N;
  StopPoll stop(interrupt);
  FilterScratch<MS> scratch(ws);
  auto& m = scratch.m;
  auto& t = scratch.t;
  m = ConstView<MS, 1>(graph.m0.data(), M, 1);
  for (int n = 0; n <= N; ++n) {
    if (stop()) return;
    for (int r = graph.row_begin[n]; r < graph.row_begin[n + 1]; ++r) {
      const ScalarFactor& f = row_factor[r];
      const int unit = graph.row_unit[r];
      const double yhat =
          graph.row_d[r] +
          (unit >= 0
               ? m(unit)
               : ConstView<MS, 1>(graph.c_pool.data() + static_cast<Eigen::Index>(graph.row_c[r]) * M, M, 1).dot(m));
      ws->yhat(r) = yhat;
      if (r + kPrefetchRows < ws->v.cols()) PrefetchForRead(ws->v.col(r + kPrefetchRows).data(), M);
      if (f.empty()) {
        ws->g(r) = 0.0;
        continue;
      }
      const double g = (f.xi - f.w * yhat) / (1.0 + f.w * ws->s(r));
      ws->g(r) = g;
      m.noalias() += g * ConstView<MS, 1>(ws->v.col(r).data(), M, 1);
    }
    if (n == N) break;
    StateProduct<MS>(t, ConstView<MS, MS>(graph.A(n).data(), M, M), m);
    m.noalias() = t;
    m.noalias() += ConstView<MS, Eigen::Dynamic>(graph.B(n).data(), M, graph.L) * ws->mU.col(n);
    m += ConstView<MS, 1>(graph.cx.col(n).data(), M, 1);
  }
}

}  // namespace

void RunForwardMeans(const FactorGraph& graph, const ScalarFactor* row_factor, ForwardFilterWorkspace* ws,
                     Interrupt* interrupt) {
  DispatchStateSize(graph.M, [&]<int MS>() { Means<MS>(graph, row_factor, ws, interrupt); });
}

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
  t.setZero(M);
  V.setZero(M, M);
  AV.setZero(M, M);
  BD.setZero(M, L);
}

void LoadInputMoments(const FactorGraph& graph, const ScalarFactor* input_factor, ForwardFilterWorkspace* ws) {
  for (int n = 0; n < graph.N; ++n) {
    for (int l = 0; l < graph.L; ++l) {
      const MomentForm mf = ToMoment(input_factor[n * graph.L + l]);
      ws->mU(l, n) = mf.mean;
      ws->VU(l, n) = mf.variance;  // callers guarantee mf.ok (Gaussian inputs)
    }
  }
}

void RunForwardFilter(const FactorGraph& graph, const ScalarFactor* input_factor, const ScalarFactor* row_factor,
                      bool keep_edges, ForwardFilterWorkspace* ws, Interrupt* interrupt) {
  if (input_factor != nullptr) LoadInputMoments(graph, input_factor, ws);
  const auto given = [row_factor](int r, double, double, const double*) { return row_factor[r]; };
  DispatchStateSize(graph.M, [&]<int MS>() { Filter<MS>(graph, row_factor, given, keep_edges, ws, interrupt); });
}

void RunForwardFilterDeciding(const FactorGraph& graph, const ScalarFactor* row_factor, RowDecider decide,
                              ForwardFilterWorkspace* ws, Interrupt* interrupt) {
  DispatchStateSize(graph.M,
                    [&]<int MS>() { Filter<MS>(graph, row_factor, decide, /*keep_edges=*/false, ws, interrupt); });
}

}  // namespace nupmpc::core
