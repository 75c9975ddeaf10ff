#include "core/algorithms/ibffd.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/util/symmetrize.h"

namespace nupmpc::core {
namespace {
// §12.4: V_e = 1/(bᵀWb + ε) for inputs with no influence on any later factor.
constexpr double kInfluenceEpsilon = 1e-15;
}  // namespace

absl::Status Ibffd::CheckApplicable(const Problem& p) {
  for (std::size_t i = 0; i < p.output_priors.size(); ++i) {
    if (p.output_priors[i].kind != PriorKind::kNone) {
      return absl::FailedPreconditionError(absl::StrCat(
          "ibffd decides inputs only; output_priors[", i, "] has a ", PriorKindName(p.output_priors[i].kind),
          " prior (use iffbdd or iake for output constraints)"));
    }
  }
  return absl::OkStatus();
}

Ibffd::Ibffd(const Problem& problem, const SolverOptions& options) : options_(options) {
  graph_ = BuildFactorGraph(problem, /*augment_inputs=*/false);
  const int M = graph_.M, N = graph_.N, L = graph_.L, NL = N * L;
  nup_.resize(NL);
  factor_.resize(NL);
  slope_.resize(NL);
  region_.resize(NL);
  polish_region_.resize(NL);
  W_step_.setZero(M, M * (N + 1));
  xi_step_.setZero(M, N + 1);
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
  Refresh(problem);
  ColdStart();
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
}

void Ibffd::MarginalizeInput(const ScalarFactor& f, const Eigen::Ref<const Eigen::VectorXd>& b,
                             Eigen::MatrixXd& W, Eigen::Ref<Eigen::VectorXd> xi) {
  // Message on the state before u enters: integrate u out of N(u; f)·μ(x + b u).
  // Written with V in the numerator (H = V/(1 + V(w + q))) so V = 0 needs no 1/V (§8.1 [fix]).
  z_.noalias() = W * b;
  const double q = b.dot(z_);
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
  xi.noalias() -= h * z_;
  W.noalias() -= H * (z_ * z_.transpose());
}

void Ibffd::BackwardFilter(const std::vector<ScalarFactor>& input_factor) {
  const FactorGraph& g = graph_;
  const int M = g.M;
  W_.setZero();
  xi_.setZero();
  for (int n = g.N; n >= 0; --n) {
    for (int r = g.row_begin[n]; r < g.row_begin[n + 1]; ++r) {
      const ScalarPrior& prior = g.row_prior[r];
      if (!prior.has_gaussian()) continue;
      const double w = 1.0 / prior.variance, xy = prior.mean / prior.variance;
      const auto c = g.c(r);
      W_.noalias() += w * (c * c.transpose());
      xi_.noalias() += (xy - w * g.row_d[r]) * c;
    }
    W_step_.middleCols(n * M, M) = W_;
    xi_step_.col(n) = xi_;
    if (n == 0) break;
    const int j = n - 1;
    for (int l = g.L - 1; l >= 0; --l) MarginalizeInput(input_factor[j * g.L + l], g.B(j).col(l), W_, xi_);
    // ξ ← Aᵀ(ξ - W cx);  W ← Aᵀ W A
    z_.noalias() = W_ * g.cx.col(j);
    xi_ -= z_;
    z_.noalias() = g.A(j).transpose() * xi_;
    xi_ = z_;
    AtW_.noalias() = g.A(j).transpose() * W_;
    W_.noalias() = AtW_ * g.A(j);
    SymmetrizeInPlace(W_);
  }
}

double Ibffd::ForwardDeciding(Pass pass, PrimalIterate* out) {
  const FactorGraph& g = graph_;
  const int M = g.M, L = g.L;
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
  for (int j = 0; j < g.N; ++j) {
    z_.noalias() = g.A(j) * x_;
    x_ = z_;
    x_ += g.cx.col(j);
    if (L == 0) continue;
    // Messages with inputs l+1..L-1 of this step marginalised: D_l for l = L-1..0.
    D_.middleCols((L - 1) * M, M) = W_step_.middleCols((j + 1) * M, M);
    d_.col(L - 1) = xi_step_.col(j + 1);
    for (int l = L - 1; l >= 1; --l) {
      W_ = D_.middleCols(l * M, M);
      xi_ = d_.col(l);
      MarginalizeInput(factor_[j * L + l], g.B(j).col(l), W_, xi_);
      D_.middleCols((l - 1) * M, M) = W_;
      d_.col(l - 1) = xi_;
    }
    for (int l = 0; l < L; ++l) {
      const int i = j * L + l;
      const auto b = g.B(j).col(l);
      const auto W = D_.middleCols(l * M, M);
      z_.noalias() = W * b;
      const double V_e = 1.0 / (b.dot(z_) + kInfluenceEpsilon);
      const double m_e = V_e * (b.dot(d_.col(l)) - z_.dot(x_));
      const Message msg{m_e, V_e};
      const ScalarPrior& prior = g.input_prior[i];
      double u;
      if (pass == Pass::kIterate) {
        Decision d;
        if (prior.is_constraint() && prior.is_hard()) {
          // The adaptive-slope rule (§8.3) decides exactly the projection; the slope only
          // grows to the smallest value that makes it feasible, for the NUP update.
          d = Decide(prior, kInfinity, msg);
          if (d.region == Region::kAtLower || d.region == Region::kAtUpper) {
            slope_[i] = std::max(slope_[i], RequiredSlope(prior, FoldGaussianPart(prior, msg)));
          }
        } else {
          d = Decide(prior, slope_[i], msg);
        }
        if (d.region != region_[i]) ++changed;
        region_[i] = d.region;
        nup_[i] = NupUpdate(prior, slope_[i], d.z);
        u = d.z;
      } else {
        u = CombineWithMessage(factor_[i], m_e, V_e);
        const Decision d = Decide(prior, prior.slope, msg);
        residual = std::max(residual, std::abs(d.z - u));
        polish_region_[i] = d.region;
      }
      out->u(l, j) = u;
      x_.noalias() += u * b;
    }
  }
  return pass == Pass::kIterate ? changed : residual;
}

int Ibffd::Iterate(PrimalIterate* out) {
  for (std::size_t i = 0; i < nup_.size(); ++i) factor_[i] = WithGaussianPart(graph_.input_prior[i], nup_[i]);
  BackwardFilter(factor_);
  const int changed = static_cast<int>(ForwardDeciding(Pass::kIterate, out));
  has_regions_ = true;
  return changed;
}

double Ibffd::Polish(PrimalIterate* out) {
  for (std::size_t i = 0; i < factor_.size(); ++i) {
    const ScalarPrior& prior = graph_.input_prior[i];
    factor_[i] = PieceFactor(prior, prior.slope, polish_region_[i]);
  }
  BackwardFilter(factor_);
  return ForwardDeciding(Pass::kPolish, out);
}

}  // namespace nupmpc::core
