#include "server/convert/keep_out_conversion.h"

#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"

namespace nupmpc::server {
namespace {

constexpr char kField[] = "spec.keep_out";

absl::Status InvalidKeepOut(const std::string& field, const std::string& rule) {
  return absl::InvalidArgumentError(absl::StrCat(kField, ".", field, ": ", rule));
}

absl::StatusOr<core::KeepOutRegion> RegionFromSpec(const v1::KeepOutRegion& r, const std::string& field) {
  core::KeepOutRegion region;
  switch (r.shape()) {
    case v1::KeepOutRegion::SHAPE_UNSPECIFIED:
    case v1::KeepOutRegion::SHAPE_ELLIPSE:
      region.shape = core::KeepOutShape::kEllipse;
      break;
    case v1::KeepOutRegion::SHAPE_RECTANGLE:
      region.shape = core::KeepOutShape::kRectangle;
      break;
    default:
      return InvalidKeepOut(field + ".shape", absl::StrCat("unknown value ", r.shape()));
  }
  if (!std::isfinite(r.centre_x())) return InvalidKeepOut(field + ".centre_x", "must be finite");
  if (!std::isfinite(r.centre_y())) return InvalidKeepOut(field + ".centre_y", "must be finite");
  if (!std::isfinite(r.half_axis_a()) || !(r.half_axis_a() > 0.0)) {
    return InvalidKeepOut(field + ".half_axis_a", absl::StrCat("must be finite and > 0, got ", r.half_axis_a()));
  }
  if (!std::isfinite(r.half_axis_b()) || r.half_axis_b() < 0.0) {
    return InvalidKeepOut(field + ".half_axis_b",
                          absl::StrCat("must be finite and > 0 (0: equal to half_axis_a), got ", r.half_axis_b()));
  }
  if (!std::isfinite(r.rotation_rad())) return InvalidKeepOut(field + ".rotation_rad", "must be finite");
  if (!std::isfinite(r.margin()) || r.margin() < 0.0) {
    return InvalidKeepOut(field + ".margin", absl::StrCat("must be finite and ≥ 0, got ", r.margin()));
  }
  if (std::isnan(r.slope()) || r.slope() < 0.0) {
    return InvalidKeepOut(field + ".slope", absl::StrCat("must be > 0 (0 or Infinity: hard), got ", r.slope()));
  }
  region.centre = Eigen::Vector2d(r.centre_x(), r.centre_y());
  region.half_axes = Eigen::Vector2d(r.half_axis_a(), r.half_axis_b() > 0.0 ? r.half_axis_b() : r.half_axis_a());
  region.rotation = r.rotation_rad();
  region.margin = r.margin();
  region.slope = r.slope() > 0.0 ? r.slope() : core::kInfinity;
  return region;
}

}  // namespace

absl::StatusOr<core::KeepOut> KeepOutFromSpec(const v1::KeepOut& spec, int num_outputs) {
  core::KeepOut keep_out;
  if (spec.first_output() >= static_cast<unsigned>(num_outputs)) {
    return InvalidKeepOut("first_output",
                          absl::StrCat("must be < num_outputs = ", num_outputs, ", got ", spec.first_output()));
  }
  if (spec.second_output() >= static_cast<unsigned>(num_outputs)) {
    return InvalidKeepOut("second_output",
                          absl::StrCat("must be < num_outputs = ", num_outputs, ", got ", spec.second_output()));
  }
  if (spec.second_output() == spec.first_output())
    return InvalidKeepOut("second_output", "must differ from first_output");
  if (spec.regions_size() == 0) return InvalidKeepOut("regions", "at least one region is required");
  if (spec.rectangle_order() != 0 && (spec.rectangle_order() < 2 || spec.rectangle_order() > 32)) {
    return InvalidKeepOut("rectangle_order", absl::StrCat("must be in [2, 32] (0: 8), got ", spec.rectangle_order()));
  }
  keep_out.first_output = static_cast<int>(spec.first_output());
  keep_out.second_output = static_cast<int>(spec.second_output());
  if (spec.rectangle_order() != 0) keep_out.rectangle_order = static_cast<int>(spec.rectangle_order());
  for (int r = 0; r < spec.regions_size(); ++r) {
    absl::StatusOr<core::KeepOutRegion> region = RegionFromSpec(spec.regions(r), absl::StrCat("regions[", r, "]"));
    if (!region.ok()) return region.status();
    keep_out.regions.push_back(*region);
  }
  return keep_out;
}

absl::StatusOr<core::SequentialOptions> SequentialOptionsFromSpec(const v1::KeepOut& spec) {
  core::SequentialOptions options;
  if (spec.max_linearisations() > 10000) {
    return InvalidKeepOut("max_linearisations", absl::StrCat("must be ≤ 10000, got ", spec.max_linearisations()));
  }
  if (spec.max_linearisations() > 0) options.max_linearisations = static_cast<int>(spec.max_linearisations());
  if (!std::isfinite(spec.step_tolerance()) || spec.step_tolerance() < 0.0) {
    return InvalidKeepOut("step_tolerance",
                          absl::StrCat("must be finite and ≥ 0 (0: 1e-6), got ", spec.step_tolerance()));
  }
  if (spec.step_tolerance() > 0.0) options.step_tolerance = spec.step_tolerance();
  return options;
}

}  // namespace nupmpc::server
