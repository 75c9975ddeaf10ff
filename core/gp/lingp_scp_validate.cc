// Validation of the linGP-SCP problem and options (declared in lingp_scp.h): the checks a
// caller's input meets before LinGpScp::Create builds anything.
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/gp/lingp_scp.h"

namespace nupmpc::gp {

absl::Status Validate(const GpMpcProblem& p) {
  if (absl::Status s = Validate(p.layout); !s.ok()) return s;
  const auto bad = [](const char* field, const std::string& rule) {
    return absl::InvalidArgumentError(absl::StrCat("GpMpcProblem.", field, ": ", rule));
  };
  if (p.horizon < 1) return bad("horizon", "must be ≥ 1");
  if (!(p.output_weight > 0.0) || !std::isfinite(p.output_weight)) return bad("output_weight", "must be finite, > 0");
  if (!(p.input_change_weight > 0.0) || !std::isfinite(p.input_change_weight)) {
    return bad("input_change_weight", "must be finite and > 0 (the NUP input's Gaussian part)");
  }
  if (!(p.input_min < p.input_max)) return bad("input_max", "must exceed input_min");
  if (!(p.rate_min <= 0.0 && p.rate_max >= 0.0 && p.rate_min < p.rate_max)) {
    return bad("rate_min/rate_max", "must bracket 0 (holding the input must be allowed)");
  }
  if (!(p.output_min < p.output_max)) return bad("output_max", "must exceed output_min");
  if (!(p.sigma_multiple >= 0.0) || !std::isfinite(p.sigma_multiple)) return bad("sigma_multiple", "must be ≥ 0");
  if (std::isnan(p.terminal_tolerance)) return bad("terminal_tolerance", "must not be NaN");
  return absl::OkStatus();
}

absl::Status Validate(const ScpOptions& o) {
  const auto bad = [](const char* field, const std::string& rule) {
    return absl::InvalidArgumentError(absl::StrCat("ScpOptions.", field, ": ", rule));
  };
  if (!(o.initial_trust_radius > 0.0)) return bad("initial_trust_radius", "must be > 0");
  if (!(o.min_trust_radius > 0.0 && o.min_trust_radius <= o.initial_trust_radius)) {
    return bad("min_trust_radius", "must be in (0, initial_trust_radius]");
  }
  if (!(o.max_trust_radius >= o.initial_trust_radius)) return bad("max_trust_radius", "must be ≥ initial");
  if (!(0.0 <= o.r0 && o.r0 < o.r1 && o.r1 < o.r2)) return bad("r0/r1/r2", "need 0 ≤ r0 < r1 < r2");
  if (!(o.beta_fail > 0.0 && o.beta_fail < 1.0)) return bad("beta_fail", "must be in (0, 1)");
  if (!(o.beta_success > 1.0)) return bad("beta_success", "must be > 1");
  if (!(o.tolerance > 0.0)) return bad("tolerance", "must be > 0");
  if (o.max_iterations < 1) return bad("max_iterations", "must be ≥ 1");
  if (!(o.penalty > 0.0) || !std::isfinite(o.penalty)) return bad("penalty", "must be finite and > 0");
  if (o.cold_start_levels < 0) return bad("cold_start_levels", "must be ≥ 0");
  return absl::OkStatus();
}

}  // namespace nupmpc::gp
