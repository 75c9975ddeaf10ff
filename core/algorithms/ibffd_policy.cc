#include "core/algorithms/ibffd_policy.h"

#include <algorithm>
#include <cmath>

#include "core/message_passing/fixed_size.h"
#include "core/util/packed_symmetric.h"
#include "core/util/prefetch.h"
#include "core/util/symmetrize.h"

namespace nupmpc::core {
namespace {
// §12.4: V_e = 1/(bᵀWb + ε) for inputs with no influence on any later factor.
constexpr double kInfluenceEpsilon = 1e-15;
}  // namespace

IbffdPolicy::IbffdPolicy(const Problem& problem, bool check_outputs) : check_outputs_(check_outputs) {
  graph_ = BuildFactorGraph(problem, /*augment_inputs=*/false);
  row_term_.resize(graph_.num_rows());
  row_bound_.resize(graph_.num_rows());
  RefreshRowTerms();
  const int M = graph_.M, L = graph_.L, NL = graph_.N * L;
  factor_.resize(NL);
  policy_region_.assign(NL, Region::kInside);
  AcquireWorkspace();
  W_.setZero(M, M);
  AtW_.setZero(M, M);
  S_.setZero(M, M);
  xi_.setZero(M);
  z_.setZero(M);
  x_.setZero(M);
  rhs_.setZero(M);
  x0_lu_ = Eigen::PartialPivLU<Eigen::MatrixXd>(M);
}

void IbffdPolicy::Refresh(const Problem& problem) {
  RefreshFactorGraph(problem, &graph_);
  RefreshRowTerms();
}

void IbffdPolicy::RefreshRowTerms() {
  for (int r = 0; r < graph_.num_rows(); ++r) {
    const ScalarPrior& prior = graph_.row_prior[r];
    const double w = 1.0 / prior.variance, xy = prior.mean / prior.variance;
    row_term_[r] = prior.has_gaussian() ? RowTerm{w, xy - w * graph_.row_d[r]} : RowTerm{};
    // Inputs' sub-problem: output kinds are none, half-spaces or boxes (the class comment).
    const bool constrained = prior.kind != PriorKind::kNone;
    row_bound_[r].lower = constrained && prior.kind != PriorKind::kAtMost ? prior.lower : -kInfinity;
    row_bound_[r].upper = constrained && prior.kind != PriorKind::kAtLeast ? prior.upper : kInfinity;
  }
}

void IbffdPolicy::ReleaseWorkspace() {
  W_step_.resize(0, 0);
  xi_step_.resize(0, 0);
  input_gain_.resize(0, 0);
  x_pred_.resize(0, 0);
  policy_released_ = policy_released_ || has_policy_;
  has_policy_ = false;
}

void IbffdPolicy::AcquireWorkspace() {
  AllocateWorkspace();
  if (policy_released_) RecomputePolicy();
}

void IbffdPolicy::AllocateWorkspace() {
  if (xi_step_.size() != 0) return;
  W_step_.setZero(PackedSymmetricSize(graph_.M), graph_.N + 1);
  xi_step_.setZero(graph_.M, graph_.N + 1);
  input_gain_.setZero(graph_.M + 2, static_cast<Eigen::Index>(graph_.N) * graph_.L);
  x_pred_.setZero(graph_.M, graph_.N + 1);
}

void IbffdPolicy::RecomputePolicy() {
  // The same filter over the same regions, shifted as often as the dropped one was.
  LoadPieceFactors(policy_region_);
  BackwardFilter(Sweep::kFull, Targets{});
  if (Interrupted()) {
    // Half a filter is no policy: the solve goes on without one (it is being stopped
    // anyway); the next AcquireWorkspace() tries again unless a cold start forgets it.
    has_policy_ = false;
    return;
  }
  ShiftPolicy(policy_shifts_);
  has_policy_ = true;
  policy_released_ = false;
}

IbffdPolicy::Memory IbffdPolicy::TakeMemory() {
  Memory memory{std::move(policy_region_), policy_shifts_, has_policy_ || policy_released_};
  policy_region_.assign(memory.regions.size(), Region::kInside);
  has_policy_ = policy_released_ = false;
  return memory;
}

void IbffdPolicy::RestoreMemory(Memory memory) {
  if (!memory.valid || memory.regions.size() != policy_region_.size()) return;
  policy_region_ = std::move(memory.regions);
  policy_shifts_ = memory.shifts;
  RecomputePolicy();
}

void IbffdPolicy::ShiftPolicy(int steps) {
  // The policy moves with its regions: the message at x[n] becomes the one at
  // x[min(n + steps, N-1)] (the last step repeats its own, as its regions do); the
  // terminal message stays. Ascending n reads only entries not yet overwritten.
  if (steps <= 0) return;
  const int N = graph_.N;
  for (int n = 0; n + 1 < N; ++n) {
    const int source = std::min(n + steps, N - 1);
    W_step_.col(n) = W_step_.col(source);
    xi_step_.col(n) = xi_step_.col(source);
  }
}

namespace {

// Integrates input u with factor f out of the backward message (W, ξ) at the state it enters,
// x + b u (§8.1). Written with V in the numerator (H = V/(1 + V(w + q))) so that V = 0 needs
// no 1/V ([fix] of [LL-BFFD] eq. 28).
template <int MS, typename WT, typename XT, typename BT, typename ZT>
void MarginalizeInput(const ScalarFactor& f, const BT& b, WT& W, XT& xi, ZT& z) {
  StateProduct<MS>(z, W, b);
  const double q = b.dot(z);
  const double bxi = b.dot(xi);
  double H, h;
  if (f.V == 0.0) {
    H = 0.0;
    h = f.m;
  } else if (f.V < kInfinity) {
    const double den = 1.0 + f.V * (f.w + q);
    H = f.V / den;
    h = (f.m + f.V * (f.xi + bxi)) / den;
  } else {
    const double den = f.w + q;
    if (den <= 0.0) return;  // a free input that influences nothing: no information
    H = 1.0 / den;
    h = (f.xi + bxi) / den;
  }
  xi.noalias() -= h * z;
  W.noalias() -= H * (z * z.transpose());
}

// What the forward pass needs of input u's message (§8.2) with the inputs after it in
// its step integrated out, (W, ξ): z = W b, bᵀz and bᵀξ, written to `out` (M + 2 values).
template <int MS, typename BT, typename WT, typename XT>
void RecordInput(const BT& b, const WT& W, const XT& xi, double* out) {
  const auto M = b.size();
  Eigen::Map<StateVector<MS>> z(out, M);
  StateProduct<MS>(z, W, b);
  out[M] = b.dot(z);
  out[M + 1] = b.dot(xi);
}

template <int MS>
using MatrixView = Eigen::Map<Eigen::Matrix<double, MS, MS>>;
template <int MS>
using VectorView = Eigen::Map<StateVector<MS>>;

}  // namespace

template <int MS>
void IbffdPolicy::BackwardFilterImpl(Sweep sweep, const Targets& targets, const PrimalIterate* predicted) {
  const FactorGraph& g = graph_;
  const int M = g.M, L = g.L;
  std::vector<ScalarFactor>& input_factor = factor_;
  MatrixView<MS> W(W_.data(), M, M), AtW(AtW_.data(), M, M);
  VectorView<MS> xi(xi_.data(), M), z(z_.data(), M);
  W.setZero();
  xi.setZero();
  StopPoll stop(interrupt_);
  for (int n = g.N; n >= 0; --n) {
    if (stop()) return;
    if (const int ahead = n - kPrefetchSteps; ahead >= 0) {
      const int packed = static_cast<int>(W_step_.rows());
      if (sweep == Sweep::kOffsets) {
        PrefetchForRead(W_step_.col(ahead).data(), packed);  // the carried gains it loads
      } else {
        PrefetchForWrite(W_step_.col(ahead).data(), packed);
      }
      PrefetchForWrite(xi_step_.col(ahead).data(), M);
      if (L > 0 && ahead < g.N) {
        PrefetchForWrite(input_gain_.col(ahead * L).data(), static_cast<int>(input_gain_.rows()) * L);
      }
    }
    for (int r = g.row_begin[n]; r < g.row_begin[n + 1]; ++r) {
      const RowTerm term = row_term_[r];
      if (term.w == 0.0) continue;  // no Gaussian part
      const int unit = g.row_unit[r];
      if (unit >= 0) {  // c = e_unit: the rank-one terms touch one entry each
        if (sweep != Sweep::kOffsets) W(unit, unit) += term.w;
        xi(unit) += term.xi;
        continue;
      }
      const auto c = ConstView<MS, 1>(g.c_pool.data() + static_cast<Eigen::Index>(g.row_c[r]) * M, M, 1);
      if (sweep != Sweep::kOffsets) W.noalias() += term.w * (c * c.transpose());
      xi.noalias() += term.xi * c;
    }
    if (sweep == Sweep::kOffsets) {
      UnpackSymmetric(W_step_.col(n).data(), W);  // the carried gains, exactly what the full filter held here
    } else {
      PackLower(W, W_step_.col(n).data());
    }
    VectorView<MS>(xi_step_.col(n).data(), M) = xi;
    if (n == 0) break;
    const int j = n - 1;
    const auto B = ConstView<MS, Eigen::Dynamic>(g.B(j).data(), M, L);
    if (sweep == Sweep::kDeciding) {
      // State entering step j's inputs as the prediction sweep found it.
      VectorView<MS> base(rhs_.data(), M), entering(x_.data(), M);
      StateProduct<MS>(base, ConstView<MS, MS>(g.A(j).data(), M, M), VectorView<MS>(x_pred_.col(j).data(), M));
      base += ConstView<MS, 1>(g.cx.col(j).data(), M, 1);
      for (int l = L - 1; l >= 0; --l) {
        const int i = j * L + l;
        const ScalarPrior& prior = g.input_prior[i];
        if (prior.kind != PriorKind::kNone) {
          entering = base;
          for (int k = 0; k < l; ++k) entering.noalias() += predicted->u(k, j) * B.col(k);
          StateProduct<MS>(z, W, B.col(l));
          const double V_e = 1.0 / (B.col(l).dot(z) + kInfluenceEpsilon);
          const double m_e = V_e * (B.col(l).dot(xi) - z.dot(entering));
          std::vector<Region>& polish_region = *targets.polish_region;
          polish_region[i] = Decide(prior, prior.slope, Message{m_e, V_e}).region;
          input_factor[i] = PieceFactor(prior, prior.slope, polish_region[i]);
        }
        RecordInput<MS>(B.col(l), W, xi, input_gain_.col(i).data());
        MarginalizeInput<MS>(input_factor[i], B.col(l), W, xi, z);
      }
    } else {
      for (int l = L - 1; l >= 0; --l) {
        RecordInput<MS>(B.col(l), W, xi, input_gain_.col(j * L + l).data());
        MarginalizeInput<MS>(input_factor[j * L + l], B.col(l), W, xi, z);
      }
    }
    // ξ ← Aᵀ(ξ - W cx);  W ← Aᵀ W A
    const auto A = ConstView<MS, MS>(g.A(j).data(), M, M);
    StateProduct<MS>(z, W, ConstView<MS, 1>(g.cx.col(j).data(), M, 1));
    xi -= z;
    StateProduct<MS>(z, A.transpose(), xi);
    xi = z;
    if (sweep == Sweep::kOffsets) continue;  // the next step's W is loaded, not computed
    StateProduct<MS>(AtW, A.transpose(), W);
    StateProduct<MS>(W, AtW, A);
    SymmetrizeInPlace(W);
  }
}

void IbffdPolicy::BackwardFilter(Sweep sweep, const Targets& targets, const PrimalIterate* predicted) {
  DispatchStateSize(graph_.M, [&]<int MS>() { BackwardFilterImpl<MS>(sweep, targets, predicted); });
}

double IbffdPolicy::ForwardDeciding(Pass pass, const Targets& targets, PrimalIterate* out) {
  return DispatchStateSize(graph_.M, [&]<int MS>() { return ForwardDecidingImpl<MS>(pass, targets, out); });
}

template <int MS>
double IbffdPolicy::ForwardDecidingImpl(Pass pass, const Targets& targets, PrimalIterate* out) {
  const FactorGraph& g = graph_;
  const int M = g.M, L = g.L;
  VectorView<MS> x(x_.data(), M), z(z_.data(), M);
  if (g.x0_fixed) {
    x_ = g.m0;
  } else {
    // x̂0 = argmax of N(m0, V0)·μ_backward: (I + V0 W) x = m0 + V0 ξ (one M×M solve).
    UnpackSymmetric(W_step_.col(0).data(), W_);
    S_.setIdentity();
    S_.noalias() += g.V0 * W_;
    rhs_ = g.m0;
    rhs_.noalias() += g.V0 * xi_step_.col(0);
    x0_lu_.compute(S_);
    x_.noalias() = x0_lu_.solve(rhs_);
  }
  out->x0 = x_;
  int changed = 0;
  double residual = 0.0;
  outputs_outside_ = false;
  const auto check_outputs = [&](int n) {
    if (pass != Pass::kPolish || !check_outputs_ || (n == 0 && g.x0_fixed)) return;  // y[0] is data then
    const double outside = OutputsOutside(n, x);
    outputs_outside_ |= outside > 0.0;
    residual = std::max(residual, outside);
  };
  StopPoll stop(interrupt_);
  for (int j = 0; j < g.N; ++j) {
    if (stop()) return pass == Pass::kIterate ? changed : kInfinity;  // incomplete: the driver discards it
    check_outputs(j);
    if (pass == Pass::kPredict) x_pred_.col(j) = x_;
    StateProduct<MS>(z, ConstView<MS, MS>(g.A(j).data(), M, M), x);
    x = z;
    x += ConstView<MS, 1>(g.cx.col(j).data(), M, 1);
    if (L == 0) continue;
    const auto B = ConstView<MS, Eigen::Dynamic>(g.B(j).data(), M, L);
    for (int l = 0; l < L; ++l) {
      const int i = j * L + l;
      const auto b = B.col(l);
      // The message of u from the later steps (W, ξ at the state it enters, the step's later
      // inputs integrated out): V_e = 1/(bᵀWb), m_e = V_e (bᵀξ - bᵀW x) (§8.2).
      const double* gain = input_gain_.col(i).data();
      const double V_e = 1.0 / (gain[M] + kInfluenceEpsilon);
      const double m_e = V_e * (gain[M + 1] - ConstView<MS, 1>(gain, M, 1).dot(x));
      const Message msg{m_e, V_e};
      const ScalarPrior& prior = g.input_prior[i];
      double u;
      if (pass == Pass::kIterate) {
        std::vector<double>& slope = *targets.nup.slope;
        std::vector<Region>& region = *targets.nup.region;
        std::vector<ScalarFactor>& nup = *targets.nup.nup;
        Decision dec;
        if (prior.is_constraint() && prior.is_hard()) {
          // The adaptive-slope rule (§8.3) decides exactly the projection; the slope only
          // grows to the smallest value that makes it feasible, for the NUP update.
          dec = Decide(prior, kInfinity, msg);
          if (dec.region == Region::kAtLower || dec.region == Region::kAtUpper) {
            slope[i] = std::max(slope[i], RequiredSlope(prior, FoldGaussianPart(prior, msg)));
          }
        } else {
          dec = Decide(prior, slope[i], msg);
        }
        if (dec.region != region[i]) ++changed;
        region[i] = dec.region;
        nup[i] = NupUpdate(prior, slope[i], dec.z);
        u = dec.z;
      } else {
        // Both sweeps go on with the decided input (Gauss-Seidel); the polish measures how
        // far it is from what the polish factors solve.
        const Decision dec = Decide(prior, prior.slope, msg);
        u = dec.z;
        if (pass == Pass::kPolish) {
          residual = std::max(residual, std::abs(dec.z - CombineWithMessage(factor_[i], m_e, V_e)));
          std::vector<Region>& polish_region = *targets.polish_region;
          polish_region[i] = NextPolishRegion(prior, polish_region[i], dec.region);
        }
      }
      out->u(l, j) = u;
      x.noalias() += u * b;
    }
  }
  check_outputs(g.N);
  if (pass == Pass::kPredict) x_pred_.col(g.N) = x_;
  return pass == Pass::kIterate ? changed : residual;
}

template <typename XT>
double IbffdPolicy::OutputsOutside(int n, const XT& x) const {
  const FactorGraph& g = graph_;
  double outside = 0.0;
  for (int r = g.row_begin[n]; r < g.row_begin[n + 1]; ++r) {
    const RowBound bound = row_bound_[r];
    if (bound.lower == -kInfinity && bound.upper == kInfinity) continue;
    const int unit = g.row_unit[r];
    const double y = (unit >= 0 ? x(unit) : g.c(r).dot(x)) + g.row_d[r];
    outside = std::max({outside, bound.lower - y, y - bound.upper});
  }
  return outside;
}

int IbffdPolicy::Iterate(NupState state, PrimalIterate* out) {
  const std::vector<ScalarFactor>& nup = *state.nup;
  for (std::size_t i = 0; i < nup.size(); ++i) factor_[i] = WithGaussianPart(graph_.input_prior[i], nup[i]);
  BackwardFilter(Sweep::kFull, Targets{});
  has_policy_ = false;  // the NUP iterate's messages are no policy of an active set
  if (Interrupted()) return -1;
  return static_cast<int>(ForwardDeciding(Pass::kIterate, Targets{state, nullptr}, out));
}

void IbffdPolicy::LoadShiftedPolicyFactors() {
  const int L = graph_.L, N = graph_.N;
  for (int n = 0; n < N; ++n) {
    const int source = std::min(n + policy_shifts_, N - 1);  // ShiftPolicy's rule
    for (int l = 0; l < L; ++l) {
      const ScalarPrior& prior = graph_.input_prior[n * L + l];
      factor_[n * L + l] = PieceFactor(prior, prior.slope, policy_region_[source * L + l]);
    }
  }
}

void IbffdPolicy::LoadPieceFactors(const std::vector<Region>& regions) {
  for (std::size_t i = 0; i < factor_.size(); ++i) {
    const ScalarPrior& prior = graph_.input_prior[i];
    factor_[i] = PieceFactor(prior, prior.slope, regions[i]);
  }
}

double IbffdPolicy::Polish(std::vector<Region>* polish_region, PrimalIterate* out) {
  const Targets targets{{}, polish_region};
  if (predict_next_) {
    // Warm start (class comment): the carried policy's offsets from the current references
    // and bounds, then predict the active set with it, then decide each input again in the
    // backward filter from the predicted states.
    predict_next_ = false;
    LoadShiftedPolicyFactors();
    BackwardFilter(Sweep::kOffsets, Targets{});
    if (Interrupted()) return kInfinity;
    LoadPieceFactors(*polish_region);
    ForwardDeciding(Pass::kPredict, targets, out);
    if (Interrupted()) return kInfinity;
    BackwardFilter(Sweep::kDeciding, targets, out);
  } else {
    LoadPieceFactors(*polish_region);
    BackwardFilter(Sweep::kFull, Targets{});
  }
  if (Interrupted()) {
    has_policy_ = false;  // W_step_/xi_step_ are half overwritten
    return kInfinity;
  }
  policy_region_ = *polish_region;  // what the filter integrated (before this pass's proposals)
  policy_shifts_ = 0;
  has_policy_ = true;
  return ForwardDeciding(Pass::kPolish, targets, out);
}

}  // namespace nupmpc::core
