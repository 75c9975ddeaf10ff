#ifndef NUPMPC_CORE_NONLINEAR_KEEP_OUT_H_
#define NUPMPC_CORE_NONLINEAR_KEEP_OUT_H_

// Keep-out regions in the plane of two outputs ([KL] §V-D, eqs. 95–97): each region r
// adds one output z_r[n] ≈ f_r(y[n]), a smooth "distance" from the region's centre in
// length units, with a half-space prior z_r ≥ threshold. f_r is nonlinear, so z_r is
// linearised around the previous plan and the problem is solved by sequential
// linearisation (core/nonlinear/sequential_solver.h).
//
// Shapes (w = diag(1/a, 1/b) Rᵀ (y - centre), a and b the half-axes, R the rotation,
// ρ = min(a, b)):
//   ellipse (circle when a = b):  f = ρ ‖w‖₂,  region f < ρ
//   rectangle:                     f = ρ ‖w‖_p (a superellipse of order p), region
//                                  f < ρ 2^{1/p}: the superellipse through the corners,
//                                  which contains the rectangle (it bulges past the
//                                  mid-points of the sides by (2^{1/p} - 1)·half-width).
//
// Each f is a norm of an affine map, so its linearisation at a point outside the region
// is a lower bound of f everywhere: a plan that satisfies the linearised (hard)
// constraints keeps out of the true region, at every linearisation, not only at the end.
// A linearisation point inside a region is pushed sideways, perpendicular to the local
// direction of travel (to the side it already leans to; left when it is exactly on the
// centre line): the tangent of the radial direction would only push it back along its path,
// and a symmetric problem (a path through the centre) would never leave the symmetric
// solution. Any unit direction keeps the lower-bound property.

#include <memory>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/nonlinear/sequential_solver.h"
#include "core/problem.h"

namespace nupmpc::core {

enum class KeepOutShape { kEllipse, kRectangle };

struct KeepOutRegion {
  KeepOutShape shape = KeepOutShape::kEllipse;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  Eigen::Vector2d half_axes = Eigen::Vector2d::Ones();  ///< along the shape's own axes, > 0
  double rotation = 0.0;                                ///< of the shape's first axis, radians counter-clockwise
  double margin = 0.0;                                  ///< extra clearance ≥ 0 (length units) added to the threshold
  double slope = kInfinity;                             ///< of the half-space prior on z; +∞ = hard

  static KeepOutRegion Circle(Eigen::Vector2d centre, double radius, double slope = kInfinity);
  static KeepOutRegion Ellipse(Eigen::Vector2d centre, double a, double b, double rotation = 0.0,
                               double slope = kInfinity);
  static KeepOutRegion Rectangle(Eigen::Vector2d centre, double half_width, double half_height, double rotation = 0.0,
                                 double slope = kInfinity);
};

struct KeepOut {
  int first_output = 0;  ///< the plane's coordinates: two distinct outputs of the plant
  int second_output = 1;
  std::vector<KeepOutRegion> regions;
  int rectangle_order = 8;  ///< superellipse order p ≥ 2 for rectangles
};

// How far `y` (a point of the plane) is outside `region`, in the region's length units
// (ρ (‖w‖ - 1), with the ∞-norm for rectangles: the true rectangle, not the superellipse).
// Negative inside; exact Euclidean distance for circles.
double KeepOutClearance(const KeepOutRegion& region, const Eigen::Vector2d& y);

// The linearisation of a linear plant with keep-out regions. The linearised problem has
// the plant's outputs first, then one output per region; the regions apply at steps
// 1..N (x[0] is given). INVALID_ARGUMENT naming the field for bad regions or outputs.
absl::StatusOr<std::unique_ptr<Linearisation>> MakeKeepOutLinearisation(const Problem& plant, const KeepOut& keep_out);

// The plant's own outputs of a plan of the linearised problem ((N+1) × K).
Eigen::MatrixXd PlantOutputs(const Solution& plan, int plant_outputs);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_NONLINEAR_KEEP_OUT_H_
