#include "core/algorithms/iake.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"

namespace nupmpc::core {

absl::Status Iake::CheckApplicable(const Problem& p) {
  for (std::size_t i = 0; i < p.input_priors.size(); ++i) {
    const ScalarPrior& prior = p.input_priors[i];
    if (prior.kind == PriorKind::kNone && !prior.has_gaussian()) {
      return absl::FailedPreconditionError(absl::StrCat(
          "iake needs a prior on every input (its forward filter has no free inputs); input_priors[", i, "] is free"));
    }
  }
  return absl::OkStatus();
}

Iake::Iake(const Problem& problem, const SolverOptions& options) : options_(options) {
  graph_ = BuildFactorGraph(problem, /*augment_inputs=*/false);
  AcquireWorkspace(problem);
  input_nup_.resize(graph_.input_prior.size());
  input_factor_.resize(graph_.input_prior.size());
  row_nup_.resize(graph_.num_rows());
  row_factor_.resize(graph_.num_rows());
  pinned_value_.assign(graph_.input_prior.size(), std::numeric_limits<double>::quiet_NaN());
  RefreshDerived();  // the graph has the values already (no second O(M³) terminal decomposition)
  ColdStart();
}

void Iake::ReleaseWorkspace() {
  fw_ = ForwardFilterWorkspace();
  sm_ = SmootherWorkspace();
  workspace_held_ = false;
}

void Iake::AcquireWorkspace(const Problem& /*problem*/) {
  if (workspace_held_) return;
  fw_.Resize(graph_, /*keep_edges=*/true);
  sm_.Resize(graph_);
  workspace_held_ = true;
}

void Iake::Refresh(const Problem& problem) {
  RefreshFactorGraph(problem, &graph_);
  RefreshDerived();
}

void Iake::RefreshDerived() {
  double scale = 0.0;
  for (const ScalarPrior& p : graph_.input_prior) {
    if (p.is_constraint()) scale = std::max({scale, std::abs(p.lower), std::abs(p.upper)});
  }
  for (const ScalarPrior& p : graph_.row_prior) {
    if (p.is_constraint()) scale = std::max({scale, std::abs(p.lower), std::abs(p.upper)});
  }
  if (scale == 0.0) scale = 1.0;
  variance_floor_ = options_.iake_variance_floor * scale * scale;
  const auto em = [](const ScalarPrior& p) { return IsNonconvex(p.kind) && p.kind != PriorKind::kLp && p.em; };
  needs_variances_ = std::any_of(graph_.input_prior.begin(), graph_.input_prior.end(), em) ||
                     std::any_of(graph_.row_prior.begin(), graph_.row_prior.end(), em);
}

void Iake::ColdStart() {
  // §6.1: inputs start from N(centre, 1) (the papers' (0, 1), centred on the prior's
  // feasible set so that shifted bounds do not start far outside); outputs with no factor.
  for (std::size_t i = 0; i < input_nup_.size(); ++i) {
    const ScalarPrior& p = graph_.input_prior[i];
    double centre = 0.0;
    switch (p.kind) {
      case PriorKind::kNone:
        input_nup_[i] = {};
        continue;
      case PriorKind::kBox:
        centre = 0.5 * (p.lower + p.upper);
        break;
      case PriorKind::kBinary:  // [KL] §V-A: N(0.5, 1) for {0, 1}, i.e. undecided
        input_nup_[i] = {0.5 * (p.lower + p.upper),
                         p.initial_variance > 0.0 ? p.initial_variance : (p.upper - p.lower) * (p.upper - p.lower), 0.0,
                         0.0};
        continue;
      case PriorKind::kAtMost:
        centre = p.upper;
        break;
      default:
        centre = p.lower;
        break;
    }
    input_nup_[i] = {centre, 1.0, 0.0, 0.0};
  }
  std::fill(row_nup_.begin(), row_nup_.end(), ScalarFactor{});
}

void Iake::ReleaseInputPins() {
  std::fill(pinned_value_.begin(), pinned_value_.end(), std::numeric_limits<double>::quiet_NaN());
}

void Iake::ShiftWarmStart() {
  const int L = graph_.L, N = graph_.N;
  for (int n = 0; n + 1 < N; ++n) {
    for (int l = 0; l < L; ++l) input_nup_[n * L + l] = input_nup_[(n + 1) * L + l];
  }
  for (int r = 0; r < graph_.num_rows(); ++r) row_nup_[r] = row_nup_[graph_.row_shift_source[r]];
}

ScalarFactor Iake::Update(const ScalarPrior& prior, double estimate, double posterior_variance) const {
  ScalarFactor f = NupUpdate(prior, EffectiveSlope(prior), estimate, posterior_variance);
  if (prior.is_constraint() && f.V < variance_floor_) f.V = variance_floor_;  // §6.3 (a)
  return f;
}

int Iake::Iterate(PrimalIterate* out) {
  for (std::size_t i = 0; i < input_nup_.size(); ++i) {
    input_factor_[i] = std::isnan(pinned_value_[i]) ? WithGaussianPart(graph_.input_prior[i], input_nup_[i])
                                                    : ScalarFactor::Pinned(pinned_value_[i]);
  }
  for (int r = 0; r < graph_.num_rows(); ++r) row_factor_[r] = WithGaussianPart(graph_.row_prior[r], row_nup_[r]);
  RunForwardFilter(graph_, input_factor_.data(), row_factor_.data(), /*keep_edges=*/true, &fw_, interrupt_);
  if (Interrupted()) return -1;  // incomplete: nothing updated
  RunSmootherBackward(graph_, fw_, needs_variances_, &sm_, interrupt_);
  if (Interrupted()) return -1;
  out->x0 = sm_.mX0;
  out->u = sm_.mU;
  for (int n = 0; n < graph_.N; ++n) {
    for (int l = 0; l < graph_.L; ++l) {
      const int i = n * graph_.L + l;
      // A pinned scalar keeps the NUP state it had: the pins are released after the solve.
      if (graph_.input_prior[i].kind == PriorKind::kNone || !std::isnan(pinned_value_[i])) continue;
      input_nup_[i] = Update(graph_.input_prior[i], sm_.mU(l, n), needs_variances_ ? sm_.VU(l, n) : 0.0);
    }
  }
  for (int r = 0; r < graph_.num_rows(); ++r) {
    if (graph_.row_prior[r].kind == PriorKind::kNone) continue;
    row_nup_[r] = Update(graph_.row_prior[r], sm_.mY(r), needs_variances_ ? sm_.VY(r) : 0.0);
  }
  return -1;
}

}  // namespace nupmpc::core
