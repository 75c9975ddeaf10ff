#include "core/algorithms/ibffd.h"

#include "absl/strings/str_cat.h"

namespace nupmpc::core {

absl::Status Ibffd::CheckApplicable(const Problem& p) {
  for (std::size_t i = 0; i < p.input_priors.size(); ++i) {
    if (IsNonconvex(p.input_priors[i].kind)) {
      return absl::FailedPreconditionError(absl::StrCat("ibffd decides convex priors only; input_priors[", i, "] is ",
                                                        PriorKindName(p.input_priors[i].kind), " (iake handles it)"));
    }
  }
  for (std::size_t i = 0; i < p.output_priors.size(); ++i) {
    if (p.output_priors[i].kind != PriorKind::kNone) {
      return absl::FailedPreconditionError(absl::StrCat("ibffd decides inputs only; output_priors[", i, "] has a ",
                                                        PriorKindName(p.output_priors[i].kind),
                                                        " prior (use iffbdd or iake for output constraints)"));
    }
  }
  return absl::OkStatus();
}

// (BuildFactorGraph, inside the policy, copied the values: a Refresh() here would redo a
// terminal weight's O(M³) eigen-decomposition.)
Ibffd::Ibffd(const Problem& problem, const SolverOptions& options)
    : options_(options), policy_(problem, /*check_outputs=*/false) {
  const std::size_t NL = policy_.graph().input_prior.size();
  nup_.resize(NL);
  slope_.resize(NL);
  region_.resize(NL);
  polish_region_.resize(NL);
  ColdStart();
}

double Ibffd::InitialSlope(const ScalarPrior& prior) const {
  if (!prior.is_hard()) return prior.slope;
  return prior.kind == PriorKind::kBox ? options_.ibffd_initial_box_slope : options_.ibffd_initial_halfspace_slope;
}

void Ibffd::ColdStart() {
  // §13 initialisation (validated): every input with a non-Gaussian prior starts from the
  // NUP factor N(0, 1). (Starting from no factor, i.e. the unconstrained optimum, lets the
  // adaptive slopes jump to huge values on stiff problems such as ibffd_2d, whose NUP
  // variances 2|u-a|/s then shrink so much that the plain iteration stalls.)
  const std::vector<ScalarPrior>& input_prior = policy_.graph().input_prior;
  for (std::size_t i = 0; i < nup_.size(); ++i) {
    const ScalarPrior& prior = input_prior[i];
    nup_[i] = prior.kind == PriorKind::kNone ? ScalarFactor{} : ScalarFactor{0.0, 1.0, 0.0, 0.0};
    slope_[i] = InitialSlope(prior);
    region_[i] = Region::kInside;
  }
  has_regions_ = false;
  policy_.Forget();
}

void Ibffd::ShiftWarmStart() {
  const int L = policy_.graph().L, N = policy_.graph().N;
  for (int n = 0; n + 1 < N; ++n) {
    for (int l = 0; l < L; ++l) {
      nup_[n * L + l] = nup_[(n + 1) * L + l];
      slope_[n * L + l] = slope_[(n + 1) * L + l];
      region_[n * L + l] = region_[(n + 1) * L + l];
    }
  }
  policy_.Shift();
}

int Ibffd::Iterate(PrimalIterate* out) {
  const int changed = policy_.Iterate({&nup_, &slope_, &region_}, out);
  if (changed >= 0) has_regions_ = true;  // -1: interrupted before deciding
  return changed;
}

void Ibffd::AdoptRegionsForPolish() {
  ActiveSetIteration::AdoptRegionsForPolish();
  policy_.StartPolish(/*carried=*/false);
}

void Ibffd::AdoptCarriedRegionsForPolish() {
  ActiveSetIteration::AdoptRegionsForPolish();
  policy_.StartPolish(/*carried=*/true);
}

}  // namespace nupmpc::core
