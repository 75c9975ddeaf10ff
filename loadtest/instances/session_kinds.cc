#include "loadtest/instances/session_kinds.h"

namespace nupmpc::bench {

std::vector<SessionKind> SessionKindsOf(const v1::ProblemSpec& base) {
  std::vector<SessionKind> kinds;
  kinds.push_back({"convex", base});

  SessionKind differences{"input differences", base};
  for (std::uint32_t l = 0; l < base.model().num_inputs(); ++l) {
    v1::ComponentPrior* moves = differences.spec.mutable_input_differences()->add_priors();
    moves->add_weight(1.0);
  }
  kinds.push_back(differences);

  // Soft (finite slope), so that no state of a closed loop makes it infeasible.
  SessionKind keep_out{"keep-out", base};
  v1::KeepOut* regions = keep_out.spec.mutable_keep_out();
  regions->set_first_output(0);
  regions->set_second_output(1);
  v1::KeepOutRegion* region = regions->add_regions();
  region->set_centre_x(0.5);
  region->set_centre_y(0.5);
  region->set_half_axis_a(0.4);
  region->set_slope(10);
  kinds.push_back(keep_out);

  SessionKind binary{"binary inputs", base};
  for (v1::ComponentPrior& input : *binary.spec.mutable_input_priors()) {
    const double lower = input.lower_size() > 0 ? input.lower(0) : -1.0;
    const double upper = input.upper_size() > 0 ? input.upper(0) : 1.0;
    input.set_kind(v1::PRIOR_KIND_BINARY);
    input.clear_lower();
    input.clear_upper();
    input.add_lower(lower);
    input.add_upper(upper);
  }
  binary.spec.mutable_options()->set_max_iterations(300);
  kinds.push_back(binary);
  return kinds;
}

}  // namespace nupmpc::bench
