#include "server/convert/session_cost.h"

#include <algorithm>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/public/footprint.h"
#include "core/public/status_macros.h"

namespace nupmpc::server {
namespace {

constexpr std::int64_t kDouble = sizeof(double);
// Matrices of P×P doubles a GP model keeps (kernel factor, and what the predictions
// reuse), and the peak of a likelihood evaluation during a fit (kernel, factor, inverse,
// gradient work).
constexpr std::int64_t kGpModelSquares = 3;
constexpr std::int64_t kGpFitSquares = 5;

std::string Mib(std::int64_t bytes) { return absl::StrCat((bytes + (1 << 20) - 1) >> 20, " MiB"); }

// Training pairs of a GpModel, from its counts alone (the data is checked later).
absl::StatusOr<std::int64_t> GpPoints(const v1::GpModel& model, const std::string& path, const SizeLimits& limits) {
  const std::int64_t lags = std::max<std::int64_t>({model.output_lags(), model.input_lags(), 1});
  const std::int64_t points = model.has_regressors() ? static_cast<std::int64_t>(model.regressors().rows())
                                                     : std::max<std::int64_t>(model.logged_outputs_size() - lags, 0);
  const std::string field = path + (model.has_regressors() ? ".regressors.rows" : ".logged_outputs (training pairs)");
  NUPMPC_RETURN_IF_ERROR(CheckLimit(field.c_str(), points, limits.max_gp_points));
  return points;
}

absl::Status CheckSessionLimits(const SessionCost& cost, const SizeLimits& limits) {
  const std::int64_t peak = std::max(cost.build_bytes, cost.session_bytes());
  if (peak > limits.max_session_bytes) {
    return absl::ResourceExhaustedError(absl::StrCat("spec: the session needs an estimated ", Mib(peak),
                                                     " of memory, over the server's per-session "
                                                     "limit (ServerLimits.max_session_bytes) of ",
                                                     Mib(limits.max_session_bytes),
                                                     "; shorten the horizon or reduce the dimensions"));
  }
  if (cost.pass_flops > limits.max_pass_flops) {
    return absl::ResourceExhaustedError(
        absl::StrCat("spec: one message-passing pass needs an estimated ", cost.pass_flops,
                     " flops, over the server's limit "
                     "(ServerLimits.max_pass_flops) of ",
                     limits.max_pass_flops, "; shorten the horizon or reduce the dimensions"));
  }
  return absl::OkStatus();
}

core::Footprint Footprint(std::int64_t M, std::int64_t L, std::int64_t K, std::int64_t N, bool per_step,
                          bool uncertain_initial_state = false, bool terminal_cost = true) {
  return core::EstimateFootprint({.num_states = M,
                                  .num_inputs = L,
                                  .num_outputs = K,
                                  .horizon = N,
                                  .a_per_step = per_step,
                                  .b_per_step = per_step,
                                  .c_per_step = per_step,
                                  .uncertain_initial_state = uncertain_initial_state,
                                  .terminal_cost = terminal_cost});
}

absl::StatusOr<SessionCost> GpSpecCost(const v1::GpMpc& gp, const SizeLimits& limits) {
  NUPMPC_ASSIGN_OR_RETURN(const std::int64_t P, GpPoints(gp.model(), "spec.gp.model", limits));
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.gp.horizon", gp.horizon(), std::min(limits.max_horizon, 10000)));
  const std::int64_t window = std::max<std::int64_t>(gp.model().output_lags(), 1) + gp.model().input_lags() + 1;
  // Each SCP subproblem is a linear time-varying NUP problem on the past window, with the
  // mean and the two chance-constraint sides as outputs.
  const core::Footprint sub = Footprint(window, 1, 4, gp.horizon(), /*per_step=*/true);
  SessionCost cost;
  const std::int64_t model_bytes = kGpModelSquares * P * P * kDouble;
  cost.resident_bytes = model_bytes + sub.problem_bytes + sub.carried_bytes;
  cost.scratch_bytes = sub.workspace_bytes;
  cost.transient_bytes = sub.transient_bytes;
  cost.build_bytes = (gp.model().has_kernel() ? model_bytes : kGpFitSquares * P * P * kDouble) + cost.session_bytes();
  cost.pass_flops = sub.flops_per_pass;
  return cost;
}

}  // namespace

absl::StatusOr<std::int64_t> GpFitBytes(const v1::GpModel& model, const std::string& path, const SizeLimits& limits) {
  NUPMPC_ASSIGN_OR_RETURN(const std::int64_t P, GpPoints(model, path, limits));
  return kGpFitSquares * P * P * kDouble;
}

absl::StatusOr<SessionCost> SpecCost(const v1::ProblemSpec& spec, const SizeLimits& limits) {
  if (spec.has_gp()) {
    NUPMPC_ASSIGN_OR_RETURN(const SessionCost cost, GpSpecCost(spec.gp(), limits));
    NUPMPC_RETURN_IF_ERROR(CheckSessionLimits(cost, limits));
    return cost;
  }
  const v1::Model& model = spec.model();
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.model.num_states", model.num_states(), limits.max_states));
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.model.num_inputs", model.num_inputs(), limits.max_inputs));
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.model.num_outputs", model.num_outputs(), limits.max_outputs));
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.model.horizon", model.horizon(), limits.max_horizon));
  std::int64_t M = model.num_states(), L = model.num_inputs(), K = model.num_outputs();
  const std::int64_t N = model.horizon();
  // Multi-level inputs become count - 1 binaries each; input differences augment the
  // state with u[-1] and add the differences as outputs.
  for (int i = 0; i < spec.input_levels_size(); ++i) {
    const std::uint32_t count = spec.input_levels(i).count();
    NUPMPC_RETURN_IF_ERROR(
        CheckLimit(absl::StrCat("spec.input_levels[", i, "].count").c_str(), count, limits.max_input_levels));
    if (count >= 2) L += count - 2;
  }
  NUPMPC_RETURN_IF_ERROR(
      CheckLimit("spec.input_levels (inputs after expanding the levels into binaries)", L, limits.max_inputs));
  if (spec.has_input_differences()) {
    M += L;
    K += L;
  }
  const bool per_step = model.a_size() > 1 || model.b_size() > 1 || model.c_size() > 1;
  core::Footprint f = Footprint(M, L, K, N, per_step, spec.initial_state().has_covariance(), spec.has_terminal());
  SessionCost cost;
  cost.resident_bytes = f.problem_bytes + f.carried_bytes;
  cost.scratch_bytes = f.workspace_bytes;
  cost.transient_bytes = f.transient_bytes;
  cost.pass_flops = f.flops_per_pass;
  if (spec.has_keep_out()) {
    const std::int64_t regions = spec.keep_out().regions_size();
    NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.keep_out.regions", regions, limits.max_keep_out_regions));
    // The linearised problem (one output per region, matrices per step) next to the plant's
    // own session that plans without regions, and the plans they exchange.
    const core::Footprint linearised = Footprint(M, L, K + regions, N, /*per_step=*/true);
    cost.resident_bytes += linearised.problem_bytes + linearised.carried_bytes + 4 * (N + 1) * (M + L + K) * kDouble;
    cost.scratch_bytes = std::max(cost.scratch_bytes, linearised.workspace_bytes);
    cost.pass_flops = std::max(cost.pass_flops, linearised.flops_per_pass);
  }
  // Create and Solve allocate transients on top of what the session keeps (the conversion
  // also holds the spec's problem while the session copies it).
  cost.build_bytes = cost.session_bytes() + cost.transient_bytes + f.problem_bytes;
  NUPMPC_RETURN_IF_ERROR(CheckSessionLimits(cost, limits));
  return cost;
}

}  // namespace nupmpc::server
