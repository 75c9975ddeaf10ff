#ifndef NUPMPC_SERVER_CONVERT_GP_CONVERSION_H_
#define NUPMPC_SERVER_CONVERT_GP_CONVERSION_H_

// proto ⇄ core for data-driven GP-MPC (ProblemSpec.gp, FitGpModel): every error names the
// proto field path and the rule, sizes over the server's limits are RESOURCE_EXHAUSTED.

#include <memory>

#include "absl/status/statusor.h"
#include "core/gp/gp_mpc_session.h"
#include "core/gp/hyperparameter_fit.h"
#include "core/gp/narx.h"
#include "nupmpc/v1/nupmpc.pb.h"
#include "server/convert/gp_model_cache.h"
#include "server/convert/spec_conversion.h"

namespace nupmpc::server {

// The layout and training pairs of a GpModel (either form of its data).
struct GpTrainingData {
  gp::NarxLayout layout;
  gp::NarxData data;
};
absl::StatusOr<GpTrainingData> GpTrainingDataFromProto(const v1::GpModel& model, const std::string& path,
                                                       const SizeLimits& limits);

// Where a fit starts without a given kernel: the data's own scales (σ_f² = variance of the
// targets, ℓ_i = spread of regressor i, σ_n² = 1 % of σ_f²), so that the start does not
// depend on the plant's units.
gp::SeArdKernel DefaultKernelStart(const gp::NarxData& data);

// The GP session of a spec whose `gp` is set (the rest of the spec must be empty). Fits the
// kernel first when the spec gives none, within `fit_options`' time and cancel flag
// (DEADLINE_EXCEEDED / CANCELLED when they stop it). With a cache, sessions of the same
// data and kernel share one factorised model.
absl::StatusOr<std::unique_ptr<gp::GpMpcSession>> GpSessionFromSpec(const v1::ProblemSpec& spec,
                                                                    const SizeLimits& limits,
                                                                    GpModelCache* cache = nullptr,
                                                                    const gp::FitOptions& fit_options = {});

// FitGpModel: validates, fits, and reports the fit's diagnostics. The fit stops at
// `fit_limits`' time (the call's deadline) or cancel flag, and the call then fails with
// DEADLINE_EXCEEDED or CANCELLED: a worker is never held by a fit nobody waits for.
absl::Status FitGpModel(const v1::FitGpModelRequest& request, const SizeLimits& limits,
                        const gp::FitOptions& fit_limits, v1::FitGpModelResponse* response);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_CONVERT_GP_CONVERSION_H_
