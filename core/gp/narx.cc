#include "core/gp/narx.h"

#include "absl/strings/str_cat.h"

namespace nupmpc::gp {

absl::Status Validate(const NarxLayout& layout) {
  if (layout.output_lags < 1) {
    return absl::InvalidArgumentError(absl::StrCat("output_lags: must be ≥ 1, got ", layout.output_lags));
  }
  if (layout.input_lags < 0) {
    return absl::InvalidArgumentError(absl::StrCat("input_lags: must be ≥ 0, got ", layout.input_lags));
  }
  return absl::OkStatus();
}

absl::StatusOr<NarxData> MakeNarxData(const NarxLayout& layout, const Eigen::VectorXd& y, const Eigen::VectorXd& u) {
  if (absl::Status valid = Validate(layout); !valid.ok()) return valid;
  if (y.size() != u.size()) {
    return absl::InvalidArgumentError(absl::StrCat("u: expected ", y.size(), " values (as y), got ", u.size()));
  }
  const int first = layout.first_step(), count = static_cast<int>(y.size()) - first;
  if (count < 1) return absl::InvalidArgumentError("y: too short for the lags");
  NarxData data;
  data.regressors.resize(count, layout.dimension());
  data.targets.resize(count);
  Eigen::VectorXd row(layout.dimension());
  for (int k = first; k < y.size(); ++k) {
    Regressor(layout, y.segment(k - layout.output_lags, layout.output_lags),
              u.segment(k - layout.input_lags, layout.input_lags + 1), &row);
    data.regressors.row(k - first) = row.transpose();
    data.targets(k - first) = y(k);
  }
  return data;
}

void Regressor(const NarxLayout& layout, const Eigen::Ref<const Eigen::VectorXd>& outputs,
               const Eigen::Ref<const Eigen::VectorXd>& inputs, Eigen::VectorXd* out) {
  out->head(layout.output_lags) = outputs;
  out->tail(layout.input_lags + 1) = inputs;
}

void PredictMultiStep(const GpModel& model, const NarxLayout& layout, const Eigen::VectorXd& past_outputs,
                      const Eigen::VectorXd& past_inputs, const Eigen::VectorXd& future, Eigen::VectorXd* means,
                      Eigen::VectorXd* variances) {
  const int l = layout.output_lags, m = layout.input_lags, H = static_cast<int>(future.size());
  // Histories with the past first, then the horizon.
  Eigen::VectorXd y(l + H), u(m + H);
  y.head(l) = past_outputs;
  u.head(m) = past_inputs;
  u.tail(H) = future;
  means->resize(H);
  variances->resize(H);
  Eigen::VectorXd x(layout.dimension());
  for (int k = 0; k < H; ++k) {
    Regressor(layout, y.segment(k, l), u.segment(k, m + 1), &x);
    double mean = 0.0, variance = 0.0;
    model.Predict(x, &mean, &variance);
    y(l + k) = mean;
    (*means)(k) = mean;
    (*variances)(k) = variance;
  }
}

}  // namespace nupmpc::gp
