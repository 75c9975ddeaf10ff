#include "core/nonlinear/keep_out.h"

#include <algorithm>
#include <cmath>

#include "Eigen/Geometry"
#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

// One region's fixed geometry: w = S (y - centre), f = ρ ‖w‖_p, keep-out f ≥ threshold.
struct RegionGeometry {
  Eigen::Matrix2d S;
  Eigen::Vector2d centre;
  double rho = 1.0;
  double p = 2.0;
  double threshold = 1.0;
};

double PNorm(const Eigen::Vector2d& w, double p) {
  if (p == 2.0) return w.norm();
  return std::pow(std::pow(std::abs(w(0)), p) + std::pow(std::abs(w(1)), p), 1.0 / p);
}

RegionGeometry Geometry(const KeepOutRegion& region, int rectangle_order) {
  RegionGeometry g;
  const Eigen::Matrix2d R = Eigen::Rotation2Dd(region.rotation).toRotationMatrix();
  g.S = region.half_axes.cwiseInverse().asDiagonal() * R.transpose();
  g.centre = region.centre;
  g.rho = region.half_axes.minCoeff();
  const bool rectangle = region.shape == KeepOutShape::kRectangle;
  g.p = rectangle ? rectangle_order : 2.0;
  g.threshold = g.rho * (rectangle ? std::pow(2.0, 1.0 / g.p) : 1.0) + region.margin;
  return g;
}

// The unit vector ĝ (in the dual norm, ‖ĝ‖_q = 1) of the linearisation z = ρ ĝᵀ w:
// the gradient of ‖w‖_p outside the region, sideways to the travel direction inside it.
Eigen::Vector2d DualDirection(const RegionGeometry& g, const Eigen::Vector2d& w, const Eigen::Vector2d& travel) {
  const double q = g.p / (g.p - 1.0);
  const auto dual_normalised = [&](const Eigen::Vector2d& v) { return Eigen::Vector2d(v / PNorm(v, q)); };
  const double norm = PNorm(w, g.p);
  if (g.rho * norm >= g.threshold) {
    // ∇‖w‖_p = sign(w) |w|^{p-1} / ‖w‖_p^{p-1}; its dual norm is 1.
    Eigen::Vector2d grad;
    for (int i = 0; i < 2; ++i) grad(i) = std::copysign(std::pow(std::abs(w(i)) / norm, g.p - 1.0), w(i));
    return dual_normalised(grad);
  }
  const Eigen::Vector2d t = g.S * travel;
  Eigen::Vector2d sideways(-t(1), t(0));
  if (sideways.dot(w) < 0.0) sideways = -sideways;
  if (sideways.squaredNorm() > 0.0) return dual_normalised(sideways);
  if (w.squaredNorm() > 0.0) return dual_normalised(w);  // standing still: radially out
  return Eigen::Vector2d(1.0, 0.0);
}

absl::Status ValidateKeepOut(const Problem& plant, const KeepOut& k) {
  const auto bad = [](const std::string& field, const std::string& rule) {
    return absl::InvalidArgumentError(absl::StrCat("keep_out.", field, ": ", rule));
  };
  for (const auto& [name, index] : {std::pair{"first_output", k.first_output}, {"second_output", k.second_output}}) {
    if (index < 0 || index >= plant.num_outputs) {
      return bad(name, absl::StrCat("must name one of the plant's ", plant.num_outputs, " outputs, got ", index));
    }
  }
  if (k.first_output == k.second_output) return bad("second_output", "must differ from first_output");
  if (k.rectangle_order < 2 || k.rectangle_order > 32) {
    return bad("rectangle_order", absl::StrCat("must be in [2, 32], got ", k.rectangle_order));
  }
  for (std::size_t r = 0; r < k.regions.size(); ++r) {
    const KeepOutRegion& region = k.regions[r];
    const std::string field = absl::StrCat("regions[", r, "]");
    if (!region.centre.allFinite()) return bad(field + ".centre", "must be finite");
    if (!region.half_axes.allFinite() || !(region.half_axes.minCoeff() > 0.0)) {
      return bad(field + ".half_axes", "must be finite and > 0");
    }
    if (!std::isfinite(region.rotation)) return bad(field + ".rotation", "must be finite");
    if (!std::isfinite(region.margin) || region.margin < 0.0) return bad(field + ".margin", "must be finite and ≥ 0");
    if (!(region.slope > 0.0)) return bad(field + ".slope", "must be > 0 (+inf for a hard constraint)");
  }
  return absl::OkStatus();
}

class KeepOutLinearisation final : public Linearisation {
 public:
  KeepOutLinearisation(const Problem& plant, const KeepOut& keep_out) : plant_(plant), keep_out_(keep_out) {
    for (const KeepOutRegion& region : keep_out.regions) {
      geometry_.push_back(Geometry(region, keep_out.rectangle_order));
    }
    BuildShape();
    plane_.resize(2, plant.horizon + 1);
  }

  const Problem& shape() const override { return shape_; }

  absl::Status SetBase(const Problem& base) override {
    NUPMPC_RETURN_IF_ERROR(CheckSameShape(plant_, base));
    NUPMPC_RETURN_IF_ERROR(Validate(base));
    plant_ = base;
    BuildShape();
    return absl::OkStatus();
  }

  void Linearise(const Solution& point, Problem* problem) const override {
    const int N = plant_.horizon, K = plant_.num_outputs;
    PlanePoints(point);
    for (int n = 0; n <= N; ++n) {
      const Eigen::Vector2d travel = plane_.col(std::min(n + 1, N)) - plane_.col(std::max(n - 1, 0));
      const Eigen::Vector2d y = plane_.col(n);
      for (std::size_t r = 0; r < geometry_.size(); ++r) {
        const RegionGeometry& g = geometry_[r];
        // z = ρ ĝᵀ S (y - c) with y = C_pair x + d_pair: one row of C and one offset.
        const Eigen::Vector2d h = g.rho * g.S.transpose() * DualDirection(g, g.S * (y - g.centre), travel);
        const int row = K + static_cast<int>(r);
        problem->C[n].row(row) =
            h(0) * plant_.C_at(n).row(keep_out_.first_output) + h(1) * plant_.C_at(n).row(keep_out_.second_output);
        problem->output_offset[n](row) = h(0) * plant_.output_offset_at(n, keep_out_.first_output) +
                                         h(1) * plant_.output_offset_at(n, keep_out_.second_output) - h.dot(g.centre);
      }
    }
  }

  double NonlinearViolation(const Solution& plan) const override {
    PlanePoints(plan);
    double violation = 0.0;
    for (int n = 1; n <= plant_.horizon; ++n) {
      for (const KeepOutRegion& region : keep_out_.regions) {
        violation = std::max(violation, region.margin - KeepOutClearance(region, plane_.col(n)));
      }
    }
    return violation;
  }

 private:
  // The plant's problem with one more output per region: its C rows and offsets are the
  // linearisation's (zero until the first Linearise()), its prior the region's half-space
  // at steps 1..N (x[0] is given: nothing to keep out).
  void BuildShape() {
    const int N = plant_.horizon, K = plant_.num_outputs, R = static_cast<int>(keep_out_.regions.size());
    shape_ = plant_;
    shape_.num_outputs = K + R;
    shape_.C.assign(N + 1, Eigen::MatrixXd::Zero(K + R, plant_.num_states));
    shape_.output_offset.assign(N + 1, Eigen::VectorXd::Zero(K + R));
    shape_.output_priors.assign(static_cast<std::size_t>(N + 1) * (K + R), ScalarPrior::Free());
    for (int n = 0; n <= N; ++n) {
      shape_.C[n].topRows(K) = plant_.C_at(n);
      for (int k = 0; k < K; ++k) {
        shape_.output_offset[n](k) = plant_.output_offset_at(n, k);
        shape_.mutable_output_prior(n, k) = plant_.output_prior(n, k);
      }
      if (n == 0) continue;
      for (int r = 0; r < R; ++r) {
        shape_.mutable_output_prior(n, K + r) =
            ScalarPrior::AtLeast(geometry_[r].threshold, keep_out_.regions[r].slope);
      }
    }
  }

  // The plan's points in the keep-out plane, from its states (the initial guess need not
  // carry outputs).
  void PlanePoints(const Solution& point) const {
    for (int n = 0; n <= plant_.horizon; ++n) {
      const auto x = point.states.row(n);
      plane_(0, n) =
          plant_.C_at(n).row(keep_out_.first_output).dot(x) + plant_.output_offset_at(n, keep_out_.first_output);
      plane_(1, n) =
          plant_.C_at(n).row(keep_out_.second_output).dot(x) + plant_.output_offset_at(n, keep_out_.second_output);
    }
  }

  Problem plant_;
  KeepOut keep_out_;
  std::vector<RegionGeometry> geometry_;
  Problem shape_;
  mutable Eigen::Matrix2Xd plane_;
};

}  // namespace

KeepOutRegion KeepOutRegion::Circle(Eigen::Vector2d centre, double radius, double slope) {
  return Ellipse(centre, radius, radius, 0.0, slope);
}

KeepOutRegion KeepOutRegion::Ellipse(Eigen::Vector2d centre, double a, double b, double rotation, double slope) {
  KeepOutRegion region;
  region.shape = KeepOutShape::kEllipse;
  region.centre = centre;
  region.half_axes = Eigen::Vector2d(a, b);
  region.rotation = rotation;
  region.slope = slope;
  return region;
}

KeepOutRegion KeepOutRegion::Rectangle(Eigen::Vector2d centre, double half_width, double half_height, double rotation,
                                       double slope) {
  KeepOutRegion region = Ellipse(centre, half_width, half_height, rotation, slope);
  region.shape = KeepOutShape::kRectangle;
  return region;
}

double KeepOutClearance(const KeepOutRegion& region, const Eigen::Vector2d& y) {
  const RegionGeometry g = Geometry(region, 2);
  const Eigen::Vector2d w = g.S * (y - g.centre);
  const double norm = region.shape == KeepOutShape::kRectangle ? w.cwiseAbs().maxCoeff() : w.norm();
  return g.rho * (norm - 1.0);
}

absl::StatusOr<std::unique_ptr<Linearisation>> MakeKeepOutLinearisation(const Problem& plant, const KeepOut& keep_out) {
  NUPMPC_RETURN_IF_ERROR(Validate(plant));
  NUPMPC_RETURN_IF_ERROR(ValidateKeepOut(plant, keep_out));
  return std::make_unique<KeepOutLinearisation>(plant, keep_out);
}

Eigen::MatrixXd PlantOutputs(const Solution& plan, int plant_outputs) { return plan.outputs.leftCols(plant_outputs); }

}  // namespace nupmpc::core
