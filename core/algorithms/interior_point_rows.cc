#include "core/algorithms/interior_point_rows.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace nupmpc::core {
namespace {

// The largest α ≤ `limit` with value + α·delta ≥ 0; NaN once anything was NaN (a breakdown
// the caller must see: std::min would drop it).
double Ratio(double value, double delta, double limit) {
  if (std::isnan(value) || std::isnan(delta) || std::isnan(limit)) return std::numeric_limits<double>::quiet_NaN();
  return delta < 0.0 ? std::min(limit, -value / delta) : limit;
}

}  // namespace

bool InteriorPointHandles(const ScalarPrior& prior) {
  if (prior.kind == PriorKind::kNone) return true;
  if (!prior.is_constraint() || !prior.is_hard()) return false;
  // A box's starting barrier precision 6/w² (Start) must be a normal number.
  const double width = prior.upper - prior.lower;
  return prior.kind != PriorKind::kBox || std::isnormal(6.0 / (width * width));
}

void InteriorPointRows::Resize(int rows) {
  const auto n = static_cast<std::size_t>(rows);
  side_.assign(n, 0);
  lo_.assign(n, Side{});
  up_.assign(n, Side{});
  kept_lo_.assign(n, Kept{});
  kept_up_.assign(n, Kept{});
  gaussian_.assign(n, GaussianPart{});
  max_step_ = kept_max_step_ = kInfinity;
}

void InteriorPointRows::Forget() { std::fill(side_.begin(), side_.end(), 0); }

ScalarFactor InteriorPointRows::Start(int r, const ScalarPrior& prior, double yhat, double V_e) {
  side_[r] = kStarted;
  lo_[r] = up_[r] = Side{};  // nothing of an earlier solve's row stays
  kept_lo_[r] = kept_up_[r] = Kept{};
  const ScalarFactor gaussian = ScalarFactor::GaussianPart(prior);
  gaussian_[r] = {.xi = gaussian.xi, .w = gaussian.w};
  if (!prior.is_constraint() || !(V_e > 0.0)) return Factor(r);
  const bool lower = prior.kind == PriorKind::kBox || prior.kind == PriorKind::kAtLeast;
  const bool upper = prior.kind == PriorKind::kBox || prior.kind == PriorKind::kAtMost;
  side_[r] = static_cast<unsigned char>(kStarted | (lower ? kLower : 0) | (upper ? kUpper : 0));
  // A box starts as the Gaussian with the moments of the uniform density on it (mean in
  // the middle, variance w²/12): slacks w/2 and barrier precisions h = λ/t = 6/w² per
  // side, so t λ = 3/2 on every side whatever the row's scale (a centred start). A
  // half-space has no width: it starts one prior standard deviation √V_e inside with the
  // same product, or at its predicted value if that is further inside.
  constexpr double kProduct = 1.5;
  const double inside = lower ? yhat - prior.lower : prior.upper - yhat;
  const double t = prior.kind == PriorKind::kBox ? 0.5 * (prior.upper - prior.lower) : std::max(inside, std::sqrt(V_e));
  const double lam = kProduct / t;
  if (lower) lo_[r] = Side{.t = t, .lam = lam, .bound = prior.lower};
  if (upper) up_[r] = Side{.t = t, .lam = lam, .bound = prior.upper};
  return Factor(r);
}

void InteriorPointRows::AimPredictor(ScalarFactor* row_factor) {
  for (int r = 0; r < static_cast<int>(side_.size()); ++r) {
    if (side_[r] == 0) continue;
    ForSides(*this, r, [](Side& s, Kept&, double) { s.target = 0.0; });
    row_factor[r] = Factor(r);
  }
}

void InteriorPointRows::AimCorrector(double sigma_mu, ScalarFactor* row_factor) {
  for (int r = 0; r < static_cast<int>(side_.size()); ++r) {
    if (side_[r] == 0) continue;
    ForSides(*this, r, [&](Side& s, Kept&, double) { s.target = sigma_mu - s.dt * s.dlam; });
    row_factor[r] = Factor(r);
  }
}

void InteriorPointRows::AimCentrality(double trial, double sigma_mu, ScalarFactor* row_factor) {
  const double low = 0.1 * sigma_mu, high = 10.0 * sigma_mu;  // Gondzio's β_min, β_max
  kept_max_step_ = max_step_;
  for (int r = 0; r < static_cast<int>(side_.size()); ++r) {
    if (side_[r] == 0) continue;
    ForSides(*this, r, [&](Side& s, Kept& kept, double) {
      kept = {.dt = s.dt, .dlam = s.dlam, .target = s.target};
      const double v = (s.t + trial * s.dt) * (s.lam + trial * s.dlam);
      // Products below the box are pulled up to it, those above pulled down (at most by
      // `high`: a large product is a variable far from its bound, harmless to the step).
      if (v < low)
        s.target += low - v;
      else if (v > high)
        s.target += std::max(high - v, -high);
    });
    row_factor[r] = Factor(r);
  }
}

void InteriorPointRows::Reject() {
  for (int r = 0; r < static_cast<int>(side_.size()); ++r) {
    ForSides(*this, r, [](Side& s, Kept& kept, double) {
      s.dt = kept.dt;
      s.dlam = kept.dlam;
      s.target = kept.target;
    });
  }
  max_step_ = kept_max_step_;
}

ScalarFactor InteriorPointRows::Factor(int r) const {
  double h = 0.0, q = 0.0;
  ForSides(*this, r, [&](const Side& s, const Kept&, double sign) {
    h += s.lam / s.t;
    q += s.lam / s.t * (s.bound + sign * s.t) + sign * s.target / s.t;
  });
  return ScalarFactor::Canonical(q + gaussian_[r].xi, h + gaussian_[r].w);
}

void InteriorPointRows::TakeDirections(const Eigen::VectorXd& z_new) {
  double step = kInfinity;
  for (int r = 0; r < static_cast<int>(side_.size()); ++r) {
    ForSides(*this, r, [&](Side& s, Kept&, double sign) {
      s.dt = sign * (z_new(r) - s.bound) - s.t;
      s.dlam = (s.target - s.t * s.lam - s.lam * s.dt) / s.t;
      step = Ratio(s.t, s.dt, step);
      step = Ratio(s.lam, s.dlam, step);
    });
  }
  max_step_ = step;
}

double InteriorPointRows::Complementarity(double step) const {
  double sum = 0.0;
  int sides = 0;
  for (int r = 0; r < static_cast<int>(side_.size()); ++r) {
    ForSides(*this, r, [&](const Side& s, const Kept&, double) {
      sum += (s.t + step * s.dt) * (s.lam + step * s.dlam);
      ++sides;
    });
  }
  return sides > 0 ? sum / sides : 0.0;
}

void InteriorPointRows::Step(double step) {
  for (int r = 0; r < static_cast<int>(side_.size()); ++r) {
    ForSides(*this, r, [&](Side& s, Kept&, double) {
      s.t += step * s.dt;
      s.lam += step * s.dlam;
    });
  }
}

Region InteriorPointRows::RegionOf(int r, double V_e, double step) const {
  const auto at_bound = [&](const Side& s) { return (s.lam + step * s.dlam) * V_e > s.t + step * s.dt; };
  if ((side_[r] & kLower) && at_bound(lo_[r])) return Region::kAtLower;
  if ((side_[r] & kUpper) && at_bound(up_[r])) return Region::kAtUpper;
  return Region::kInside;
}

double InteriorPointRows::largest_multiplier() const {
  double largest = 0.0;
  for (std::size_t r = 0; r < side_.size(); ++r) {
    if (active(static_cast<int>(r))) largest = std::max({largest, lo_[r].lam, up_[r].lam});
  }
  return largest;
}

}  // namespace nupmpc::core
