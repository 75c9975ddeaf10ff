#include "core/priors/scalar_rules.h"

#include <algorithm>
#include <cmath>

namespace nupmpc::core {
namespace {

double Pos(double t) { return t > 0.0 ? t : 0.0; }

// Penalty part of κ for a finite slope (no Gaussian part).
double KindPenalty(const ScalarPrior& p, double z) {
  const double s = p.slope;
  switch (p.kind) {
    case PriorKind::kNone:
      return 0.0;
    case PriorKind::kL1:
      return s * std::abs(z - p.lower);
    case PriorKind::kHuber: {
      const double t = std::abs(z - p.lower), r2 = p.radius * p.radius;
      return t <= s * r2 ? t * t / (2.0 * r2) + 0.5 * s * s * r2 : s * t;
    }
    case PriorKind::kAtLeast:
      return p.is_hard() ? 0.0 : s * Pos(p.lower - z);
    case PriorKind::kAtMost:
      return p.is_hard() ? 0.0 : s * Pos(z - p.upper);
    case PriorKind::kBox:
      return p.is_hard() ? 0.0 : s * (Pos(p.lower - z) + Pos(z - p.upper));
    case PriorKind::kLp:
      return s * std::pow(std::abs(z - p.lower), p.exponent);
    // log|z| is unbounded below at the centre: NUV priors are reported by their sparsity,
    // not in J; a binary's indicator is 0 on the levels (the distance is the violation).
    case PriorKind::kPlainNuv:
    case PriorKind::kSmoothedNuv:
    case PriorKind::kBinary:
      return 0.0;
  }
  return 0.0;
}

}  // namespace

double PriorCost(const ScalarPrior& p, double z) {
  double cost = KindPenalty(p, z);
  if (p.has_gaussian()) {
    const double d = z - p.mean;
    cost += 0.5 * d * d / p.variance;
  }
  return cost;
}

double HardViolation(const ScalarPrior& p, double z) {
  if (p.kind == PriorKind::kBinary) return std::min(std::abs(z - p.lower), std::abs(z - p.upper));
  if (!p.is_constraint() || !p.is_hard()) return 0.0;
  switch (p.kind) {
    case PriorKind::kAtLeast:
      return Pos(p.lower - z);
    case PriorKind::kAtMost:
      return Pos(z - p.upper);
    case PriorKind::kBox:
      return Pos(p.lower - z) + Pos(z - p.upper);
    default:
      return 0.0;
  }
}

Message FoldGaussianPart(const ScalarPrior& p, Message e) {
  if (!p.has_gaussian()) return e;
  const double gV = p.variance;
  if (e.V == kInfinity) return {p.mean, gV};
  const double den = gV + e.V;
  return {(e.m * gV + p.mean * e.V) / den, e.V * gV / den};
}

Decision Decide(const ScalarPrior& p, double s, Message extrinsic) {
  const Message f = FoldGaussianPart(p, extrinsic);
  const double m = f.m, V = f.V;
  const bool finite = s < kInfinity;
  switch (p.kind) {
    case PriorKind::kNone:
      return {m, Region::kInside};
    case PriorKind::kL1: {
      const double t = m - p.lower, sv = s * V;
      if (t > sv) return {m - sv, Region::kAbove};
      if (t < -sv) return {m + sv, Region::kBelow};
      return {p.lower, Region::kAtLower};
    }
    case PriorKind::kHuber: {
      const double t = m - p.lower, r2 = p.radius * p.radius;
      if (t > s * (V + r2)) return {m - s * V, Region::kAbove};
      if (t < -s * (V + r2)) return {m + s * V, Region::kBelow};
      return {p.lower + r2 * t / (V + r2), Region::kInside};
    }
    case PriorKind::kAtLeast:
      if (m > p.lower) return {m, Region::kInside};
      if (finite && m < p.lower - s * V) return {m + s * V, Region::kBelow};
      return {p.lower, Region::kAtLower};
    case PriorKind::kAtMost:
      if (m < p.upper) return {m, Region::kInside};
      if (finite && m > p.upper + s * V) return {m - s * V, Region::kAbove};
      return {p.upper, Region::kAtUpper};
    case PriorKind::kBox:
      if (m < p.lower) {
        if (finite && m < p.lower - s * V) return {m + s * V, Region::kBelow};
        return {p.lower, Region::kAtLower};
      }
      if (m > p.upper) {
        if (finite && m > p.upper + s * V) return {m - s * V, Region::kAbove};
        return {p.upper, Region::kAtUpper};
      }
      return {m, Region::kInside};
    case PriorKind::kPlainNuv:  // type-II rule (§5.1)
      if ((m - p.lower) * (m - p.lower) > V) return {m - V / (m - p.lower), Region::kInside};
      return {p.lower, Region::kAtLower};
    case PriorKind::kSmoothedNuv:
    case PriorKind::kLp:
    case PriorKind::kBinary:
      return {m, Region::kInside};  // no deciding rule: IAKE only
  }
  return {m, Region::kInside};
}

ScalarFactor NupUpdate(const ScalarPrior& p, double s, double x, double posterior_variance) {
  // EM variants add the posterior variance of the scalar to the squared distances (§5.1).
  const double vp = p.em ? posterior_variance : 0.0;
  switch (p.kind) {
    case PriorKind::kNone:
      return {};
    case PriorKind::kL1:
      return {p.lower, std::abs(x - p.lower) / s, 0.0, 0.0};
    case PriorKind::kHuber: {
      const double r2 = p.radius * p.radius;
      return {p.lower, std::max(r2, std::abs(x - p.lower) / s), 0.0, 0.0};
    }
    case PriorKind::kAtLeast: {
      const double d = std::abs(x - p.lower);
      return {p.lower + d, 2.0 * d / s, 0.0, 0.0};
    }
    case PriorKind::kAtMost: {
      const double d = std::abs(x - p.upper);
      return {p.upper - d, 2.0 * d / s, 0.0, 0.0};
    }
    case PriorKind::kBox: {
      // Product forms (§5.1 notes): no 0/0 at a bound, where V = 0 and m = x.
      const double da = std::abs(x - p.lower), db = std::abs(x - p.upper), sum = da + db;
      return {(p.lower * db + p.upper * da) / sum, 2.0 * da * db / (s * sum), 0.0, 0.0};
    }
    case PriorKind::kPlainNuv: {
      const double d = x - p.lower;
      return {p.lower, vp + d * d, 0.0, 0.0};
    }
    case PriorKind::kSmoothedNuv: {
      const double d = x - p.lower;
      return {p.lower, std::max(p.radius * p.radius, vp + d * d), 0.0, 0.0};
    }
    case PriorKind::kLp:
      return {p.lower, std::pow(std::abs(x - p.lower), 2.0 - p.exponent) / (s * p.exponent), 0.0, 0.0};
    case PriorKind::kBinary: {
      const double xc = std::clamp(x, p.lower, p.upper);
      const double da = xc - p.lower, db = xc - p.upper;
      const double sa = vp + da * da, sb = vp + db * db, sum = sa + sb;  // sum > 0: lower < upper
      return {(p.lower * sb + p.upper * sa) / sum, sa * sb / sum, 0.0, 0.0};
    }
  }
  return {};
}

Region NextPolishRegion(const ScalarPrior& prior, Region solved, Region decided) {
  if (prior.kind != PriorKind::kBox) return decided;
  const bool was_low = solved == Region::kAtLower || solved == Region::kBelow;
  const bool was_high = solved == Region::kAtUpper || solved == Region::kAbove;
  const bool now_low = decided == Region::kAtLower || decided == Region::kBelow;
  const bool now_high = decided == Region::kAtUpper || decided == Region::kAbove;
  return (was_low && now_high) || (was_high && now_low) ? Region::kInside : decided;
}

ScalarFactor PieceFactor(const ScalarPrior& p, double s, Region region) {
  switch (region) {
    case Region::kAtLower:
      return ScalarFactor::Pinned(p.lower);
    case Region::kAtUpper:
      return ScalarFactor::Pinned(p.upper);
    default:
      break;
  }
  ScalarFactor f = ScalarFactor::GaussianPart(p);
  if (p.kind == PriorKind::kHuber && region == Region::kInside) {
    const double r2 = p.radius * p.radius;
    f.xi += p.lower / r2;
    f.w += 1.0 / r2;
  } else if (region == Region::kBelow) {
    f.xi += s;  // cost -s·z: factor exp(+s z)
  } else if (region == Region::kAbove) {
    f.xi -= s;
  }
  return f;
}

namespace {
// Dual NUP of a half-space ([LL-dual] §9.4 table). `bound` = a for z ≥ a (sign = +1),
// b for z ≤ b (sign = -1). Hard: s = ∞.
ScalarFactor HalfSpaceDual(double bound, double sign, double s, double y_dual, double gamma) {
  const double u = std::abs(y_dual);
  if (u == 0.0) return {};
  if (s == kInfinity) {
    return ScalarFactor::Canonical((2.0 * bound + sign * gamma) * u / gamma, 2.0 * u / gamma);
  }
  const double p = std::abs(y_dual + sign * s);
  const double den = gamma * (p + u);
  return ScalarFactor::Canonical((2.0 * bound * p * u + sign * s * gamma * u) / den, 2.0 * p * u / den);
}
}  // namespace

ScalarFactor DualNupFactor(const ScalarPrior& p, double y_dual, double gamma) {
  switch (p.kind) {
    case PriorKind::kAtLeast:
      return HalfSpaceDual(p.lower, +1.0, p.slope, y_dual, gamma);
    case PriorKind::kAtMost:
      return HalfSpaceDual(p.upper, -1.0, p.slope, y_dual, gamma);
    case PriorKind::kBox:
      return y_dual <= 0.0 ? HalfSpaceDual(p.lower, +1.0, p.slope, y_dual, gamma)
                           : HalfSpaceDual(p.upper, -1.0, p.slope, y_dual, gamma);
    case PriorKind::kL1: {
      const double s = p.slope, pp = std::abs(y_dual + s), q = std::abs(y_dual - s);
      const double den = gamma * (pp + q);
      return ScalarFactor::Canonical((2.0 * p.lower * pp * q + s * gamma * (q - pp)) / den, 2.0 * pp * q / den);
    }
    default:
      return {};
  }
}

double GammaNext(const ScalarPrior& p, Message f) {
  const double s = p.slope;
  switch (p.kind) {
    case PriorKind::kL1:
      return std::abs(f.m - p.lower) - s * f.V;
    case PriorKind::kAtLeast:
      return p.is_hard() ? f.m - p.lower : std::max(p.lower - f.m - s * f.V, f.m - p.lower);
    case PriorKind::kAtMost:
      return p.is_hard() ? p.upper - f.m : std::max(p.upper - f.m, f.m - p.upper - s * f.V);
    case PriorKind::kBox:
      if (p.is_hard()) return 0.5 * (p.upper - p.lower);
      return std::max({0.5 * (p.upper - p.lower), p.lower - f.m - s * f.V, f.m - p.upper - s * f.V});
    default:
      return 0.0;
  }
}

double GammaInitial(const ScalarPrior& p) {
  if (p.kind == PriorKind::kBox) return 0.5 * (p.upper - p.lower);
  return 1e-12;
}

double RequiredSlope(const ScalarPrior& p, Message f) {
  switch (p.kind) {
    case PriorKind::kAtLeast:
      return (p.lower - f.m) / f.V;
    case PriorKind::kAtMost:
      return (f.m - p.upper) / f.V;
    case PriorKind::kBox:
      return std::max(p.lower - f.m, f.m - p.upper) / f.V;
    default:
      return 0.0;
  }
}

}  // namespace nupmpc::core
