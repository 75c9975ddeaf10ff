#ifndef NUPMPC_CORE_GP_NARX_H_
#define NUPMPC_CORE_GP_NARX_H_

// NARX regressors for GP models of dynamic systems ([Nghiem] (7)–(8)), single input,
// single output:
//   y[k] = f(y[k-l], ..., y[k-1], u[k-m], ..., u[k])
// The regressor is [y[k-l..k-1], u[k-m..k]] (dimension l + m + 1), oldest first.
// Multi-step prediction uses the zero-variance method: predicted means are fed back as
// the lagged outputs, variances are not propagated ([Nghiem] §III-A).

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "core/gp/gp_model.h"

namespace nupmpc::gp {

struct NarxLayout {
  int output_lags = 1;  ///< l ≥ 1
  int input_lags = 0;   ///< m ≥ 0 (0: only the current input u[k])
  int dimension() const { return output_lags + input_lags + 1; }
  int first_step() const { return std::max(output_lags, input_lags); }  ///< first k with a full regressor
};
absl::Status Validate(const NarxLayout& layout);

struct NarxData {
  Eigen::MatrixXd regressors;  ///< one row per usable k
  Eigen::VectorXd targets;     ///< y[k]
};

// Training pairs from a logged experiment (y and u of the same length T).
absl::StatusOr<NarxData> MakeNarxData(const NarxLayout& layout, const Eigen::VectorXd& y, const Eigen::VectorXd& u);

// The regressor of y[k] from the past outputs and inputs, written to `out` (size
// layout.dimension()): `outputs(j)` is y[k-l+j], `inputs(j)` is u[k-m+j] (j = 0..m).
void Regressor(const NarxLayout& layout, const Eigen::Ref<const Eigen::VectorXd>& outputs,
               const Eigen::Ref<const Eigen::VectorXd>& inputs, Eigen::VectorXd* out);

// Zero-variance multi-step prediction over the inputs `future` (H values, u[t..t+H-1]):
// `past_outputs` are y[t-l..t-1], `past_inputs` u[t-m..t-1] (m values). Writes the means
// ȳ[t..t+H-1] and the latent variances σ²[t..t+H-1].
void PredictMultiStep(const GpModel& model, const NarxLayout& layout, const Eigen::VectorXd& past_outputs,
                      const Eigen::VectorXd& past_inputs, const Eigen::VectorXd& future, Eigen::VectorXd* means,
                      Eigen::VectorXd* variances);

}  // namespace nupmpc::gp

#endif  // NUPMPC_CORE_GP_NARX_H_
