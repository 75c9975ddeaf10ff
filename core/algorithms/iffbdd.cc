#include "core/algorithms/iffbdd.h"

#include <algorithm>
#include <cmath>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "core/message_passing/fixed_size.h"
#include "core/util/prefetch.h"

namespace nupmpc::core {
namespace {

bool RowKindSupported(PriorKind kind) {
  return kind == PriorKind::kNone || kind == PriorKind::kL1 || kind == PriorKind::kAtLeast ||
         kind == PriorKind::kAtMost || kind == PriorKind::kBox;
}

}  // namespace

absl::Status Iffbdd::CheckApplicable(const Problem& p) {
  for (std::size_t i = 0; i < p.input_priors.size(); ++i) {
    const ScalarPrior& prior = p.input_priors[i];
    if (!prior.has_gaussian()) {
      return absl::FailedPreconditionError(absl::StrCat(
          "iffbdd needs a Gaussian part (input weight R > 0) on every input; input_priors[", i, "] has none"));
    }
    if (!RowKindSupported(prior.kind)) {
      return absl::FailedPreconditionError(
          absl::StrCat("iffbdd has no dual rule for input_priors[", i, "] of kind ", PriorKindName(prior.kind)));
    }
  }
  for (std::size_t i = 0; i < p.output_priors.size(); ++i) {
    if (!RowKindSupported(p.output_priors[i].kind)) {
      return absl::FailedPreconditionError(absl::StrCat("iffbdd has no dual rule for output_priors[", i, "] of kind ",
                                                        PriorKindName(p.output_priors[i].kind)));
    }
  }
  return absl::OkStatus();
}

Iffbdd::Iffbdd(const Problem& problem, const SolverOptions& options)
    : graph_(BuildFactorGraph(problem, std::any_of(problem.input_priors.begin(), problem.input_priors.end(),
                                                   [](const ScalarPrior& p) { return p.kind != PriorKind::kNone; }))),
      // The graph is augmented iff some input is constrained.
      input_polish_(problem, graph_, /*inputs_constrained=*/graph_.augmented, options),
      interior_point_(options) {
  const int R = graph_.num_rows();
  input_factor_.resize(graph_.input_prior.size());
  nup_.resize(R);
  row_factor_.resize(R);
  gamma_.resize(R);
  region_.resize(R);
  polish_region_.resize(R);
  costate_.setZero(graph_.M);
  scratch_.setZero(graph_.M);
  step_costate_.setZero(graph_.M, graph_.N + 1);
  row_dual_.setZero(R);
  row_step_.resize(R);
  for (int n = 0; n <= graph_.N; ++n) {
    for (int r = graph_.row_begin[n]; r < graph_.row_begin[n + 1]; ++r) row_step_[r] = n;
  }
  RefreshDerived();  // the graphs have the values already (no more O(M³) terminal decompositions)
  AcquireWorkspace(problem);
  ColdStart();
}

void Iffbdd::ReleaseWorkspace() {
  fw_ = ForwardFilterWorkspace();
  interior_point_.Release();
  newton_z_.resize(0);
  workspace_held_ = false;
  input_polish_.Release();
}

void Iffbdd::AcquireWorkspace(const Problem& problem) {
  input_polish_.Acquire(problem, interrupt_);
  if (workspace_held_) return;
  fw_.Resize(graph_, /*keep_edges=*/false);
  interior_point_.Acquire(graph_);
  if (interior_point_.MayUse(graph_)) newton_z_.setZero(graph_.num_rows());
  LoadInputMoments(graph_, input_factor_.data(), &fw_);
  workspace_held_ = true;
}

void Iffbdd::Refresh(const Problem& problem) {
  RefreshFactorGraph(problem, &graph_);
  input_polish_.Refresh(problem);
  RefreshDerived();
}

void Iffbdd::RefreshOutputPriors(const Problem& problem) {
  RefreshFactorGraphOutputPriors(problem, &graph_);
  interior_point_.Decide(graph_);
}

void Iffbdd::RefreshDerived() {
  interior_point_.Decide(graph_);
  for (std::size_t i = 0; i < input_factor_.size(); ++i) {
    input_factor_[i] = ScalarFactor::GaussianPart(graph_.input_prior[i]);
  }
  if (workspace_held_) LoadInputMoments(graph_, input_factor_.data(), &fw_);  // else on acquiring
  // Hard boxes keep γ = (b-a)/2 exactly ([LL-dual] eq. 59); others keep their adapted γ.
  for (int r = 0; r < graph_.num_rows(); ++r) {
    const ScalarPrior& prior = graph_.row_prior[r];
    if (prior.kind == PriorKind::kBox && prior.is_hard()) gamma_[r] = GammaInitial(prior);
  }
}

void Iffbdd::ColdStart() {
  for (int r = 0; r < graph_.num_rows(); ++r) {
    nup_[r] = ScalarFactor{};
    gamma_[r] = GammaInitial(graph_.row_prior[r]);
    region_[r] = Region::kInside;
  }
  has_regions_ = false;
  has_duals_ = false;
  interior_point_.ForgetSolve();
  input_polish_.ColdStart();
}

void Iffbdd::ShiftWarmStart() {
  // Sources are always rows of a later step, i.e. higher indices: ascending order is safe.
  for (int r = 0; r < graph_.num_rows(); ++r) {
    const int src = graph_.row_shift_source[r];
    nup_[r] = nup_[src];
    gamma_[r] = gamma_[src];
    region_[r] = region_[src];
    row_dual_(r) = row_dual_(src);
  }
  for (int n = 0; n < graph_.N; ++n) step_costate_.col(n) = step_costate_.col(n + 1);
  interior_point_.ForgetSolve();
  input_polish_.Shift();
  for (int r = 0; r < graph_.num_rows(); ++r) {
    const ScalarPrior& prior = graph_.row_prior[r];
    if (prior.kind == PriorKind::kBox && prior.is_hard()) gamma_[r] = GammaInitial(prior);
  }
}

int Iffbdd::Iterate(PrimalIterate* out) {
  if (interior_point_.iterates()) {
    const int changed = interior_point_.Iterate(*this, &region_, out);
    if (changed == IffbddInteriorPoint::kInterrupted) return -1;
    if (changed != IffbddInteriorPoint::kBreakdown) {
      has_regions_ = true;
      largest_dual_ = interior_point_.largest_multiplier();
      return changed;
    }
    // A breakdown: this solve goes on with the dual iteration (IffbddInteriorPoint::Iterate).
  }
  for (int r = 0; r < graph_.num_rows(); ++r) row_factor_[r] = WithGaussianPart(graph_.row_prior[r], nup_[r]);
  RunForwardFilter(graph_, nullptr, row_factor_.data(), /*keep_edges=*/false, &fw_, interrupt_);
  if (Interrupted()) return -1;  // incomplete: the carried state is untouched so far
  const int changed = static_cast<int>(Backward(Pass::kIterate, out));
  has_regions_ = true;
  return changed;
}

bool Iffbdd::StartingPass(InteriorPointRows* rows, PrimalIterate* out) {
  for (int r = 0; r < graph_.num_rows(); ++r) row_factor_[r] = ScalarFactor::GaussianPart(graph_.row_prior[r]);
  RunForwardFilterDeciding(
      graph_, row_factor_.data(),
      [this, rows](int r, double yhat, double s, const double*) {
        return row_factor_[r] = rows->Start(r, graph_.row_prior[r], yhat, s);
      },
      &fw_, interrupt_);
  if (Interrupted()) return false;
  Backward(Pass::kNewton, out);
  return true;
}

bool Iffbdd::NewtonPass(bool full_filter, PrimalIterate* out) {
  if (full_filter) {
    RunForwardFilter(graph_, nullptr, row_factor_.data(), /*keep_edges=*/false, &fw_, interrupt_);
  } else {
    RunForwardMeans(graph_, row_factor_.data(), &fw_, interrupt_);
  }
  if (Interrupted()) return false;
  Backward(Pass::kNewton, out);
  return !Interrupted();
}

void Iffbdd::AdoptRegionsForPolish() {
  ActiveSetIteration::AdoptRegionsForPolish();
  decide_forward_next_ = false;
  polishing_inputs_ = StartInputPolish(/*carried=*/false);
}

void Iffbdd::AdoptCarriedRegionsForPolish() {
  ActiveSetIteration::AdoptRegionsForPolish();
  interior_point_.UseDualIteration();
  decide_forward_next_ = has_duals_;
  polishing_inputs_ = StartInputPolish(/*carried=*/true);
}

bool Iffbdd::OutputConstraintsInside() const {
  for (int r = 0; r < graph_.num_rows(); ++r) {
    if (graph_.row_origin[r].type == RowOrigin::Type::kOutput && graph_.row_prior[r].kind != PriorKind::kNone &&
        region_[r] != Region::kInside) {
      return false;
    }
  }
  return true;
}

bool Iffbdd::StartInputPolish(bool carried) {
  // With an active output constraint the sub-problem would be the wrong one.
  if (!input_polish_.active() || !OutputConstraintsInside()) return false;
  input_polish_.Start(region_, carried);
  return true;
}

void Iffbdd::AcceptPolishRegions() {
  if (!polishing_inputs_) {
    ActiveSetIteration::AcceptPolishRegions();
    // The sub-problem's carried policy belongs to an older active set now.
    input_polish_.ForgetPolicy();
    return;
  }
  input_polish_.ProposedRegions(&region_);  // outputs inactive
  // This algorithm's duals are the last own pass's, not the accepted solution's.
  has_duals_ = false;
  polishing_inputs_ = false;
}

ScalarFactor Iffbdd::DecideRowForward(int r, double yhat, double s, const double* v_data) {
  const FactorGraph& g = graph_;
  const ScalarPrior& prior = g.row_prior[r];
  if (s > 0.0) {
    // m_e = ŷ - vᵀx̃ (§9.3), with x̃ the costate of the rows after r: the later steps'
    // (entering this step) plus this step's later rows, all from the last backward pass.
    const int n = row_step_[r];
    const Eigen::Map<const Eigen::VectorXd> v(v_data, g.M);
    double costate_dot = v.dot(step_costate_.col(n));
    for (int later = r + 1; later < g.row_begin[n + 1]; ++later) {
      if (row_dual_(later) == 0.0) continue;
      costate_dot += row_dual_(later) * (g.row_unit[later] >= 0 ? v(g.row_unit[later]) : v.dot(g.c(later)));
    }
    polish_region_[r] = Decide(prior, prior.slope, Message{yhat - costate_dot, s}).region;
  }
  row_factor_[r] = PieceFactor(prior, prior.slope, polish_region_[r]);
  return row_factor_[r];
}

double Iffbdd::Polish(PrimalIterate* out) {
  if (polishing_inputs_ && input_polish_.outputs_outside()) {
    // The last pass (not accepted) left an output outside its bounds: an output constraint
    // became active. Go on with this algorithm's own polish from the input regions the
    // sub-problem proposed; outputs start inside and the pass proposes the violated ones.
    polishing_inputs_ = false;
    decide_forward_next_ = false;
    input_polish_.ProposedRegions(&polish_region_);
  }
  if (polishing_inputs_) return input_polish_.Polish(out);
  for (int r = 0; r < graph_.num_rows(); ++r) {
    const ScalarPrior& prior = graph_.row_prior[r];
    row_factor_[r] = prior.kind == PriorKind::kNone ? ScalarFactor::GaussianPart(prior)
                                                    : PieceFactor(prior, prior.slope, polish_region_[r]);
  }
  if (decide_forward_next_) {
    // Only the first pass: repeating the forward sweep in later corrections settles a few
    // more steps in two passes but makes others cycle.
    decide_forward_next_ = false;
    RunForwardFilterDeciding(
        graph_, row_factor_.data(),
        [this](int r, double yhat, double s, const double* v) { return DecideRowForward(r, yhat, s, v); }, &fw_,
        interrupt_);
  } else {
    RunForwardFilter(graph_, nullptr, row_factor_.data(), /*keep_edges=*/false, &fw_, interrupt_);
  }
  if (Interrupted()) return kInfinity;
  return Backward(Pass::kPolish, out);
}

double Iffbdd::Backward(Pass pass, PrimalIterate* out) {
  return DispatchStateSize(graph_.M, [&]<int MS>() { return BackwardImpl<MS>(pass, out); });
}

template <int MS>
double Iffbdd::BackwardImpl(Pass pass, PrimalIterate* out) {
  const FactorGraph& g = graph_;
  const int M = g.M;
  // x̃: the dual of the state (the costate). Fixed-size kernels keep it in a register block.
  std::conditional_t<MS == Eigen::Dynamic, Eigen::VectorXd&, StateVector<MS>> xt = costate_;
  xt.setZero();
  int changed = 0;
  double residual = 0.0;
  double largest_dual = 0.0;
  // A step of this pass is cheap (Aᵀx̃ and one dot product per row): its own interval.
  const double rows_per_step = static_cast<double>(g.num_rows()) / (g.N + 1);
  StopPoll stop(interrupt_, interrupt_ != nullptr ? interrupt_->IntervalFor(2.0 * M * (M + rows_per_step + g.L)) : 1);
  // x̃ += c ỹ for row r (a unit row adds to one entry).
  const auto AddRow = [&](int r, double y_dual) {
    if (g.row_unit[r] >= 0) {
      xt(g.row_unit[r]) += y_dual;
    } else {
      xt.noalias() += y_dual * ConstView<MS, 1>(g.c_pool.data() + static_cast<Eigen::Index>(g.row_c[r]) * M, M, 1);
    }
  };
  for (int n = g.N; n >= 0; --n) {
    if (stop()) return pass == Pass::kIterate ? changed : kInfinity;  // incomplete: the driver discards it
    if (pass != Pass::kNewton) View<MS, 1>(step_costate_.col(n).data(), M, 1) = xt;
    for (int r = g.row_begin[n + 1] - 1; r >= g.row_begin[n]; --r) {
      if (r >= kPrefetchRows) PrefetchForRead(fw_.v.col(r - kPrefetchRows).data(), M);
      if (pass == Pass::kNewton) {
        // Only the pass's factors matter here (no deciding): the priors are not read and
        // the kept duals not written, which long horizons would stream for nothing.
        const ScalarFactor& f = row_factor_[r];
        const double V_e = fw_.s(r);
        if (!(V_e > 0.0)) {  // fixed by data (or skipped by the filter: unconstrained, no factor)
          newton_z_(r) = fw_.yhat(r);
          continue;
        }
        const double m_e = fw_.yhat(r) - ConstView<MS, 1>(fw_.v.col(r).data(), M, 1).dot(xt);
        if (f.empty()) {  // a bound whose barrier underflowed: the row's value, no update
          newton_z_(r) = m_e;
          continue;
        }
        const double z = CombineWithMessage(f, m_e, V_e);
        newton_z_(r) = z;
        const double y_dual = (m_e - z) / V_e;
        if (y_dual != 0.0) AddRow(r, y_dual);
        continue;
      }
      row_dual_(r) = 0.0;
      const ScalarPrior& prior = g.row_prior[r];
      if (prior.kind == PriorKind::kNone && !prior.has_gaussian()) continue;
      const double V_e = fw_.s(r);
      if (!(V_e > 0.0)) continue;  // output fixed by data (§9.3): ỹ = 0, no update
      const double m_e = fw_.yhat(r) - ConstView<MS, 1>(fw_.v.col(r).data(), M, 1).dot(xt);
      const Message msg{m_e, V_e};
      double y_dual;
      if (pass == Pass::kIterate) {
        const Decision d = Decide(prior, prior.slope, msg);
        y_dual = (m_e - d.z) / V_e;  // Moreau: the exact dual decision
        if (prior.kind != PriorKind::kNone) {
          largest_dual = std::max(largest_dual, std::abs(y_dual));
          if (d.region != region_[r]) ++changed;
          region_[r] = d.region;
          gamma_[r] = std::max(gamma_[r], GammaNext(prior, FoldGaussianPart(prior, msg)));
          const double nup_dual = prior.has_gaussian() ? y_dual - (d.z - prior.mean) / prior.variance : y_dual;
          nup_[r] = DualNupFactor(prior, nup_dual, gamma_[r]);
        }
      } else {
        const double z = CombineWithMessage(row_factor_[r], m_e, V_e);
        y_dual = (m_e - z) / V_e;
        if (prior.kind != PriorKind::kNone) {
          const Decision d = Decide(prior, prior.slope, msg);
          residual = std::max(residual, std::abs(d.z - z));
          polish_region_[r] = NextPolishRegion(prior, polish_region_[r], d.region);
        }
      }
      row_dual_(r) = y_dual;
      if (y_dual != 0.0) AddRow(r, y_dual);
    }
    if (n == 0) break;
    const int j = n - 1;
    const auto B = ConstView<MS, Eigen::Dynamic>(g.B(j).data(), M, g.L);
    for (int l = 0; l < g.L; ++l) out->u(l, j) = fw_.mU(l, j) - fw_.VU(l, j) * B.col(l).dot(xt);
    const auto At = ConstView<MS, MS>(g.A(j).data(), M, M).transpose();
    if constexpr (MS == Eigen::Dynamic) {
      scratch_.noalias() = At * xt;
      xt = scratch_;
    } else {
      xt = StateVector<MS>(At.lazyProduct(xt));  // coefficient-based: see StateProduct
    }
  }
  scratch_.noalias() = g.m0;
  scratch_.noalias() -= g.V0 * xt;
  out->x0 = scratch_.head(g.base_M);
  if (pass != Pass::kNewton) has_duals_ = true;
  if (pass == Pass::kIterate) largest_dual_ = largest_dual;
  return pass == Pass::kIterate ? changed : residual;
}

}  // namespace nupmpc::core
