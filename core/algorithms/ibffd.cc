#include "core/algorithms/ibffd.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/message_passing/fixed_size.h"
#include "core/util/symmetrize.h"

namespace nupmpc::core {
namespace {
// §12.4: V_e = 1/(bᵀWb + ε) for inputs with no influence on any later factor.
constexpr double kInfluenceEpsilon = 1e-15;
}  // namespace

absl::Status Ibffd::CheckApplicable(const Problem& p) {
  for (std::size_t i = 0; i < p.input_priors.size(); ++i) {
    if (IsNonconvex(p.input_priors[i].kind)) {
      return absl::FailedPreconditionError(absl::StrCat("ibffd decides convex priors only; input_priors[", i,
                                                        "] is ", PriorKindName(p.input_priors[i].kind),
                                                        " (iake handles it)"));
    }
  }
  for (std::size_t i = 0; i < p.output_priors.size(); ++i) {
    if (p.output_priors[i].kind != PriorKind::kNone) {
      return absl::FailedPreconditionError(absl::StrCat(
          "ibffd decides inputs only; output_priors[", i, "] has a ", PriorKindName(p.output_priors[i].kind),
          " prior (use iffbdd or iake for output constraints)"));
    }
  }
  return absl::OkStatus();
}

Ibffd::Ibffd(const Problem& problem, const SolverOptions& options) : Ibffd(problem, options, false) {}

std::unique_ptr<Ibffd> Ibffd::ForInputSubproblem(const Problem& problem, const SolverOptions& options) {
  return std::unique_ptr<Ibffd>(new Ibffd(problem, options, /*check_outputs=*/true));
}

Ibffd::Ibffd(const Problem& problem, const SolverOptions& options, bool check_outputs)
    : options_(options), check_outputs_(check_outputs) {
  graph_ = BuildFactorGraph(problem, /*augment_inputs=*/false);
  const int M = graph_.M, N = graph_.N, L = graph_.L, NL = N * L;
  nup_.resize(NL);
  factor_.resize(NL);
  slope_.resize(NL);
  region_.resize(NL);
  polish_region_.resize(NL);
  policy_region_.assign(NL, Region::kInside);
  AcquireWorkspace(problem);
  W_.setZero(M, M);
  AtW_.setZero(M, M);
  S_.setZero(M, M);
  xi_.setZero(M);
  z_.setZero(M);
  x_.setZero(M);
  rhs_.setZero(M);
  D_.setZero(M, M * std::max(L, 1));
  d_.setZero(M, std::max(L, 1));
  x0_lu_ = Eigen::PartialPivLU<Eigen::MatrixXd>(M);
  // (BuildFactorGraph copied the values: a Refresh() here would redo a terminal weight's
  // O(M³) eigen-decomposition.)
  ColdStart();
}

void Ibffd::ReleaseWorkspace() {
  W_step_.resize(0, 0);
  xi_step_.resize(0, 0);
  x_pred_.resize(0, 0);
  policy_released_ = policy_released_ || has_policy_;
  has_policy_ = false;
}

void Ibffd::AcquireWorkspace(const Problem& /*problem*/) {
  if (xi_step_.size() == 0) {
    W_step_.setZero(graph_.M, graph_.M * (graph_.N + 1));
    xi_step_.setZero(graph_.M, graph_.N + 1);
    x_pred_.setZero(graph_.M, graph_.N + 1);
  }
  if (policy_released_) RecomputePolicy();
}

void Ibffd::RecomputePolicy() {
  // The same filter over the same regions, shifted as often as the dropped one was.
  LoadPieceFactors(policy_region_);
  BackwardFilter(Sweep::kFull);
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

Ibffd::PolicyMemory Ibffd::TakePolicyMemory() {
  PolicyMemory memory{std::move(policy_region_), policy_shifts_, has_policy_ || policy_released_};
  policy_region_.assign(memory.regions.size(), Region::kInside);
  has_policy_ = policy_released_ = false;
  return memory;
}

void Ibffd::RestorePolicy(PolicyMemory memory) {
  if (!memory.valid || memory.regions.size() != policy_region_.size()) return;
  policy_region_ = std::move(memory.regions);
  policy_shifts_ = memory.shifts;
  RecomputePolicy();
}

void Ibffd::Refresh(const Problem& problem) { RefreshFactorGraph(problem, &graph_); }

double Ibffd::InitialSlope(const ScalarPrior& prior) const {
  if (!prior.is_hard()) return prior.slope;
  return prior.kind == PriorKind::kBox ? options_.ibffd_initial_box_slope : options_.ibffd_initial_halfspace_slope;
}

void Ibffd::ColdStart() {
  // §13 initialisation (validated): every input with a non-Gaussian prior starts from the
  // NUP factor N(0, 1). (Starting from no factor, i.e. the unconstrained optimum, lets the
  // adaptive slopes jump to huge values on stiff problems such as ibffd_2d, whose NUP
  // variances 2|u-a|/s then shrink so much that the plain iteration stalls.)
  for (std::size_t i = 0; i < nup_.size(); ++i) {
    const ScalarPrior& prior = graph_.input_prior[i];
    nup_[i] = prior.kind == PriorKind::kNone ? ScalarFactor{} : ScalarFactor{0.0, 1.0, 0.0, 0.0};
    slope_[i] = InitialSlope(prior);
    region_[i] = Region::kInside;
  }
  has_regions_ = false;
  has_policy_ = false;
  policy_released_ = false;
}

void Ibffd::ShiftWarmStart() {
  const int L = graph_.L, N = graph_.N;
  for (int n = 0; n + 1 < N; ++n) {
    for (int l = 0; l < L; ++l) {
      nup_[n * L + l] = nup_[(n + 1) * L + l];
      slope_[n * L + l] = slope_[(n + 1) * L + l];
      region_[n * L + l] = region_[(n + 1) * L + l];
    }
  }
  if (has_policy_) ShiftPolicy(1);
  if (has_policy_ || policy_released_) ++policy_shifts_;
}

void Ibffd::ShiftPolicy(int steps) {
  // The policy moves with its regions: the message at x[n] becomes the one at
  // x[min(n + steps, N-1)] (the last step repeats its own, as its regions do); the
  // terminal message stays. Ascending n reads only entries not yet overwritten.
  if (steps <= 0) return;
  const int M = graph_.M, N = graph_.N;
  for (int n = 0; n + 1 < N; ++n) {
    const int source = std::min(n + steps, N - 1);
    W_step_.middleCols(n * M, M) = W_step_.middleCols(source * M, M);
    xi_step_.col(n) = xi_step_.col(source);
  }
}

void Ibffd::AdoptRegionsForPolish() {
  ActiveSetIteration::AdoptRegionsForPolish();
  predict_next_ = false;
}

void Ibffd::AdoptCarriedRegionsForPolish() {
  ActiveSetIteration::AdoptRegionsForPolish();
  predict_next_ = has_policy_;
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

template <int MS>
using MatrixView = Eigen::Map<Eigen::Matrix<double, MS, MS>>;
template <int MS>
using VectorView = Eigen::Map<StateVector<MS>>;

}  // namespace

template <int MS>
void Ibffd::BackwardFilterImpl(Sweep sweep, const PrimalIterate* predicted) {
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
    for (int r = g.row_begin[n]; r < g.row_begin[n + 1]; ++r) {
      const ScalarPrior& prior = g.row_prior[r];
      if (!prior.has_gaussian()) continue;
      const double w = 1.0 / prior.variance, xy = prior.mean / prior.variance;
      const auto c = ConstView<MS, 1>(g.c_pool.data() + static_cast<Eigen::Index>(g.row_c[r]) * M, M, 1);
      if (sweep != Sweep::kOffsets) W.noalias() += w * (c * c.transpose());
      xi.noalias() += (xy - w * g.row_d[r]) * c;
    }
    MatrixView<MS> stored_W(W_step_.data() + static_cast<Eigen::Index>(n) * M * M, M, M);
    if (sweep == Sweep::kOffsets) {
      W = stored_W;  // the carried gains, exactly what the full filter held here
    } else {
      stored_W = W;
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
          polish_region_[i] = Decide(prior, prior.slope, Message{m_e, V_e}).region;
          input_factor[i] = PieceFactor(prior, prior.slope, polish_region_[i]);
        }
        MarginalizeInput<MS>(input_factor[i], B.col(l), W, xi, z);
      }
    } else {
      for (int l = L - 1; l >= 0; --l) MarginalizeInput<MS>(input_factor[j * L + l], B.col(l), W, xi, z);
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

void Ibffd::BackwardFilter(Sweep sweep, const PrimalIterate* predicted) {
  DispatchStateSize(graph_.M, [&]<int MS>() { BackwardFilterImpl<MS>(sweep, predicted); });
}

double Ibffd::ForwardDeciding(Pass pass, PrimalIterate* out) {
  return DispatchStateSize(graph_.M, [&]<int MS>() { return ForwardDecidingImpl<MS>(pass, out); });
}

template <int MS>
double Ibffd::ForwardDecidingImpl(Pass pass, PrimalIterate* out) {
  const FactorGraph& g = graph_;
  const int M = g.M, L = g.L;
  VectorView<MS> x(x_.data(), M), z(z_.data(), M), xi(xi_.data(), M);
  MatrixView<MS> W(W_.data(), M, M);
  if (g.x0_fixed) {
    x_ = g.m0;
  } else {
    // x̂0 = argmax of N(m0, V0)·μ_backward: (I + V0 W) x = m0 + V0 ξ (one M×M solve).
    S_.setIdentity();
    S_.noalias() += g.V0 * W_step_.leftCols(M);
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
    // Messages with inputs l+1..L-1 of this step marginalised: D_l for l = L-1..0.
    const auto D = [&](int l) { return MatrixView<MS>(D_.data() + static_cast<Eigen::Index>(l) * M * M, M, M); };
    const auto d = [&](int l) { return VectorView<MS>(d_.col(l).data(), M); };
    D(L - 1) = MatrixView<MS>(W_step_.data() + static_cast<Eigen::Index>(j + 1) * M * M, M, M);
    d(L - 1) = VectorView<MS>(xi_step_.col(j + 1).data(), M);
    for (int l = L - 1; l >= 1; --l) {
      W = D(l);
      xi = d(l);
      MarginalizeInput<MS>(factor_[j * L + l], B.col(l), W, xi, z);
      D(l - 1) = W;
      d(l - 1) = xi;
    }
    for (int l = 0; l < L; ++l) {
      const int i = j * L + l;
      const auto b = B.col(l);
      StateProduct<MS>(z, D(l), b);
      const double V_e = 1.0 / (b.dot(z) + kInfluenceEpsilon);
      const double m_e = V_e * (b.dot(d(l)) - z.dot(x));
      const Message msg{m_e, V_e};
      const ScalarPrior& prior = g.input_prior[i];
      double u;
      if (pass == Pass::kIterate) {
        Decision dec;
        if (prior.is_constraint() && prior.is_hard()) {
          // The adaptive-slope rule (§8.3) decides exactly the projection; the slope only
          // grows to the smallest value that makes it feasible, for the NUP update.
          dec = Decide(prior, kInfinity, msg);
          if (dec.region == Region::kAtLower || dec.region == Region::kAtUpper) {
            slope_[i] = std::max(slope_[i], RequiredSlope(prior, FoldGaussianPart(prior, msg)));
          }
        } else {
          dec = Decide(prior, slope_[i], msg);
        }
        if (dec.region != region_[i]) ++changed;
        region_[i] = dec.region;
        nup_[i] = NupUpdate(prior, slope_[i], dec.z);
        u = dec.z;
      } else {
        // Both sweeps go on with the decided input (Gauss-Seidel); the polish measures how
        // far it is from what the polish factors solve.
        const Decision dec = Decide(prior, prior.slope, msg);
        u = dec.z;
        if (pass == Pass::kPolish) {
          residual = std::max(residual, std::abs(dec.z - CombineWithMessage(factor_[i], m_e, V_e)));
          polish_region_[i] = NextPolishRegion(prior, polish_region_[i], dec.region);
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
double Ibffd::OutputsOutside(int n, const XT& x) const {
  const FactorGraph& g = graph_;
  double outside = 0.0;
  for (int r = g.row_begin[n]; r < g.row_begin[n + 1]; ++r) {
    const ScalarPrior& prior = g.row_prior[r];
    if (prior.kind == PriorKind::kNone) continue;
    const double y = g.c(r).dot(x) + g.row_d[r];
    if (prior.kind != PriorKind::kAtMost) outside = std::max(outside, prior.lower - y);
    if (prior.kind != PriorKind::kAtLeast) outside = std::max(outside, y - prior.upper);
  }
  return outside;
}

int Ibffd::Iterate(PrimalIterate* out) {
  for (std::size_t i = 0; i < nup_.size(); ++i) factor_[i] = WithGaussianPart(graph_.input_prior[i], nup_[i]);
  BackwardFilter(Sweep::kFull);
  has_policy_ = false;  // the NUP iterate's messages are no policy of an active set
  if (Interrupted()) return -1;
  const int changed = static_cast<int>(ForwardDeciding(Pass::kIterate, out));
  has_regions_ = true;
  return changed;
}

void Ibffd::LoadShiftedPolicyFactors() {
  const int L = graph_.L, N = graph_.N;
  for (int n = 0; n < N; ++n) {
    const int source = std::min(n + policy_shifts_, N - 1);  // ShiftPolicy's rule
    for (int l = 0; l < L; ++l) {
      const ScalarPrior& prior = graph_.input_prior[n * L + l];
      factor_[n * L + l] = PieceFactor(prior, prior.slope, policy_region_[source * L + l]);
    }
  }
}

void Ibffd::LoadPieceFactors(const std::vector<Region>& regions) {
  for (std::size_t i = 0; i < factor_.size(); ++i) {
    const ScalarPrior& prior = graph_.input_prior[i];
    factor_[i] = PieceFactor(prior, prior.slope, regions[i]);
  }
}

double Ibffd::Polish(PrimalIterate* out) {
  if (predict_next_) {
    // Warm start (class comment): the carried policy's offsets from the current references
    // and bounds, then predict the active set with it, then decide each input again in the
    // backward filter from the predicted states.
    predict_next_ = false;
    LoadShiftedPolicyFactors();
    BackwardFilter(Sweep::kOffsets);
    if (Interrupted()) return kInfinity;
    LoadPieceFactors(polish_region_);
    ForwardDeciding(Pass::kPredict, out);
    if (Interrupted()) return kInfinity;
    BackwardFilter(Sweep::kDeciding, out);
  } else {
    LoadPieceFactors(polish_region_);
    BackwardFilter(Sweep::kFull);
  }
  if (Interrupted()) {
    has_policy_ = false;  // W_step_/xi_step_ are half overwritten
    return kInfinity;
  }
  policy_region_ = polish_region_;  // what the filter integrated (before this pass's proposals)
  policy_shifts_ = 0;
  has_policy_ = true;
  return ForwardDeciding(Pass::kPolish, out);
}

}  // namespace nupmpc::core
