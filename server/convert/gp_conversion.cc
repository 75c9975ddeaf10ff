#include "server/convert/gp_conversion.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/public/deadline.h"
#include "core/public/status_macros.h"
#include "server/convert/invalid_argument.h"

namespace nupmpc::server {
namespace {

absl::StatusOr<Eigen::VectorXd> FiniteVector(const google::protobuf::RepeatedField<double>& values,
                                             const std::string& path) {
  Eigen::VectorXd out(values.size());
  for (int i = 0; i < values.size(); ++i) {
    if (!std::isfinite(values[i])) return InvalidArgument(path, "[", i, "] = ", values[i], ": must be finite");
    out(i) = values[i];
  }
  return out;
}

absl::StatusOr<gp::SeArdKernel> KernelFromProto(const v1::GpKernel& k, int dimension, const std::string& path) {
  const auto positive = [&](double v, const std::string& field) -> absl::Status {
    if (!(v > 0.0) || !std::isfinite(v)) return InvalidArgument(path, ".", field, " = ", v, ": must be finite and > 0");
    return absl::OkStatus();
  };
  NUPMPC_RETURN_IF_ERROR(positive(k.signal_variance(), "signal_variance"));
  NUPMPC_RETURN_IF_ERROR(positive(k.noise_variance(), "noise_variance"));
  if (k.length_scales_size() != dimension) {
    return InvalidArgument(path, ".length_scales: expected ", dimension,
                           " values (one per regressor: output_lags + input_lags + 1), got ", k.length_scales_size());
  }
  gp::SeArdKernel kernel;
  kernel.signal_variance = k.signal_variance();
  kernel.noise_variance = k.noise_variance();
  kernel.length_scales.resize(dimension);
  for (int i = 0; i < dimension; ++i) {
    NUPMPC_RETURN_IF_ERROR(positive(k.length_scales(i), absl::StrCat("length_scales[", i, "]")));
    kernel.length_scales(i) = k.length_scales(i);
  }
  return kernel;
}

void KernelToProto(const gp::SeArdKernel& kernel, v1::GpKernel* out) {
  out->set_signal_variance(kernel.signal_variance);
  out->set_noise_variance(kernel.noise_variance);
  out->clear_length_scales();
  for (Eigen::Index i = 0; i < kernel.length_scales.size(); ++i) out->add_length_scales(kernel.length_scales(i));
}

// DEADLINE_EXCEEDED or CANCELLED for a fit its limits stopped.
absl::Status StoppedFit(const gp::FitResult& fit, const gp::FitOptions& options, int points) {
  const std::string done = absl::StrCat(" after ", fit.iterations, " L-BFGS iterations on ", points,
                                        " points; fit fewer points or allow more time");
  if (options.cancel != nullptr && options.cancel->load()) {
    return absl::CancelledError(absl::StrCat("the fit was cancelled", done));
  }
  return absl::DeadlineExceededError(absl::StrCat("the deadline ended the fit", done));
}

// The kernel of a GpModel: its own, or fitted from the default start within `fit_options`.
absl::StatusOr<gp::SeArdKernel> KernelFor(const v1::GpModel& model, const GpTrainingData& training,
                                          const std::string& path, const gp::FitOptions& fit_options) {
  if (model.has_kernel()) return KernelFromProto(model.kernel(), training.layout.dimension(), path + ".kernel");
  absl::StatusOr<gp::FitResult> fit = gp::FitHyperparameters(training.data.regressors, training.data.targets,
                                                             DefaultKernelStart(training.data), fit_options);
  if (!fit.ok())
    return absl::Status(fit.status().code(), absl::StrCat(path, " (fitting the kernel): ", fit.status().message()));
  if (fit->stopped) return StoppedFit(*fit, fit_options, static_cast<int>(training.data.targets.size()));
  return fit->kernel;
}

}  // namespace

absl::StatusOr<GpTrainingData> GpTrainingDataFromProto(const v1::GpModel& model, const std::string& path,
                                                       const SizeLimits& limits) {
  GpTrainingData out;
  out.layout.output_lags = model.output_lags() == 0 ? 1 : static_cast<int>(model.output_lags());
  if (model.input_lags() > 64 || model.output_lags() > 64) {
    return InvalidArgument(path, ".output_lags/input_lags: at most 64 each");
  }
  out.layout.input_lags = static_cast<int>(model.input_lags());
  const int d = out.layout.dimension();
  const bool logged = model.logged_outputs_size() > 0 || model.logged_inputs_size() > 0;
  const bool pairs = model.has_regressors() || model.targets_size() > 0;
  if (logged == pairs) {
    return InvalidArgument(path,
                           ": give the training data either as logged_outputs + logged_inputs or as regressors + "
                           "targets (exactly one of the two)");
  }
  if (logged) {
    NUPMPC_RETURN_IF_ERROR(CheckLimit((path + ".logged_outputs").c_str(), model.logged_outputs_size(),
                                      static_cast<long long>(limits.max_gp_points) + out.layout.first_step()));
    if (model.logged_inputs_size() != model.logged_outputs_size()) {
      return InvalidArgument(path, ".logged_inputs: expected ", model.logged_outputs_size(),
                             " values (as logged_outputs), got ", model.logged_inputs_size());
    }
    NUPMPC_ASSIGN_OR_RETURN(const Eigen::VectorXd y, FiniteVector(model.logged_outputs(), path + ".logged_outputs"));
    NUPMPC_ASSIGN_OR_RETURN(const Eigen::VectorXd u, FiniteVector(model.logged_inputs(), path + ".logged_inputs"));
    if (y.size() <= out.layout.first_step()) {
      return InvalidArgument(path, ".logged_outputs: ", y.size(),
                             " samples give no training pair for these lags (need more than ", out.layout.first_step(),
                             ")");
    }
    NUPMPC_ASSIGN_OR_RETURN(out.data, gp::MakeNarxData(out.layout, y, u));
  } else {
    const int P = static_cast<int>(model.regressors().rows());
    NUPMPC_RETURN_IF_ERROR(CheckLimit((path + ".regressors.rows").c_str(), P, limits.max_gp_points));
    if (P < 1) return InvalidArgument(path, ".regressors: needs at least one row");
    NUPMPC_ASSIGN_OR_RETURN(out.data.regressors, MatrixFromProto(model.regressors(), P, d, path + ".regressors"));
    if (model.targets_size() != P) {
      return InvalidArgument(path, ".targets: expected ", P, " values (one per regressor row), got ",
                             model.targets_size());
    }
    NUPMPC_ASSIGN_OR_RETURN(out.data.targets, FiniteVector(model.targets(), path + ".targets"));
  }
  const long long P = out.data.targets.size();
  NUPMPC_RETURN_IF_ERROR(CheckLimit((path + " (training pairs)").c_str(), P, limits.max_gp_points));
  // The factorised model holds P×P matrices: the same memory bound as a linear model.
  NUPMPC_RETURN_IF_ERROR(
      CheckLimit((path + " (training pairs squared, in scalars)").c_str(), P * P, limits.max_scalars));
  return out;
}

gp::SeArdKernel DefaultKernelStart(const gp::NarxData& data) {
  const auto spread = [](const Eigen::VectorXd& v) {
    const double mean = v.mean();
    return v.size() > 1 ? std::sqrt((v.array() - mean).square().sum() / static_cast<double>(v.size() - 1)) : 0.0;
  };
  gp::SeArdKernel kernel;
  const double target_spread = spread(data.targets);
  kernel.signal_variance = target_spread > 0.0 ? target_spread * target_spread : 1.0;
  kernel.noise_variance = 0.01 * kernel.signal_variance;
  kernel.length_scales.resize(data.regressors.cols());
  for (Eigen::Index i = 0; i < data.regressors.cols(); ++i) {
    const double s = spread(data.regressors.col(i));
    kernel.length_scales(i) = s > 0.0 ? s : 1.0;
  }
  return kernel;
}

absl::StatusOr<std::unique_ptr<gp::GpMpcSession>> GpSessionFromSpec(const v1::ProblemSpec& spec,
                                                                    const SizeLimits& limits, GpModelCache* cache,
                                                                    const gp::FitOptions& fit_options) {
  // A GP spec describes nothing else: refuse what would be silently ignored.
  if (spec.has_model()) return InvalidArgument("spec.model: must be empty when spec.gp is set (the GP is the model)");
  if (spec.input_priors_size() > 0)
    return InvalidArgument("spec.input_priors: must be empty when spec.gp is set (use spec.gp.input_min/max)");
  if (spec.output_priors_size() > 0)
    return InvalidArgument("spec.output_priors: must be empty when spec.gp is set (use spec.gp)");
  if (spec.has_terminal())
    return InvalidArgument("spec.terminal: must be empty when spec.gp is set (use spec.gp.terminal_tolerance)");
  if (spec.input_levels_size() > 0) return InvalidArgument("spec.input_levels: cannot be combined with spec.gp");
  if (spec.has_input_differences())
    return InvalidArgument("spec.input_differences: must be empty when spec.gp is set (use spec.gp.rate_min/max)");
  if (spec.has_keep_out()) return InvalidArgument("spec.keep_out: cannot be combined with spec.gp");
  const v1::SolverOptions& o = spec.options();
  if (o.algorithm() != v1::ALGORITHM_UNSPECIFIED || o.max_iterations() != 0 || o.objective_tolerance() != 0.0 ||
      o.violation_tolerance() != 0.0 || o.elastic_slope() != 0.0 || o.elastic_after_iterations() != 0) {
    return InvalidArgument("spec.options: GP sessions take time_limit_ms only (SCP limits are in spec.gp.scp)");
  }
  if (!(o.time_limit_ms() >= 0.0) || !std::isfinite(o.time_limit_ms())) {
    return InvalidArgument("spec.options.time_limit_ms = ", o.time_limit_ms(), ": must be finite and >= 0");
  }
  const v1::GpMpc& g = spec.gp();
  if (!g.has_model()) return InvalidArgument("spec.gp.model: required");
  NUPMPC_ASSIGN_OR_RETURN(const GpTrainingData training, GpTrainingDataFromProto(g.model(), "spec.gp.model", limits));

  gp::GpMpcProblem problem;
  problem.layout = training.layout;
  if (g.horizon() == 0) return InvalidArgument("spec.gp.horizon: must be >= 1");
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.gp.horizon", g.horizon(), std::min(limits.max_horizon, 10000)));
  problem.horizon = static_cast<int>(g.horizon());
  problem.output_weight = g.output_weight();
  problem.input_change_weight = g.input_change_weight();
  problem.input_min = g.input_min();
  problem.input_max = g.input_max();
  problem.rate_min = g.rate_min();
  problem.rate_max = g.rate_max();
  problem.output_min = g.output_min();
  problem.output_max = g.output_max();
  problem.sigma_multiple = g.sigma_multiple();
  problem.terminal_tolerance = g.terminal_tolerance();
  // The core names its own fields (GpMpcProblem.x): say it in the spec's terms.
  if (absl::Status valid = gp::Validate(problem); !valid.ok()) {
    std::string message(valid.message());
    const std::string prefix = "GpMpcProblem.";
    if (message.rfind(prefix, 0) == 0) message = "spec.gp." + message.substr(prefix.size());
    return absl::InvalidArgumentError(message);
  }
  // The cold start holds levels of the input box, and the rate limit bounds the steps.
  for (const auto& [value, field] : {std::pair{g.input_min(), "input_min"}, std::pair{g.input_max(), "input_max"},
                                     std::pair{g.rate_min(), "rate_min"}, std::pair{g.rate_max(), "rate_max"}}) {
    if (!std::isfinite(value)) return InvalidArgument("spec.gp.", field, " = ", value, ": must be finite");
  }

  gp::ScpOptions options;
  const v1::GpScpOptions& s = g.scp();
  if (s.max_iterations() > 10000) return InvalidArgument("spec.gp.scp.max_iterations: at most 10000");
  if (s.max_iterations() > 0) options.max_iterations = static_cast<int>(s.max_iterations());
  const auto optional_positive = [](double v, double* out, const char* field) -> absl::Status {
    if (v == 0.0) return absl::OkStatus();
    if (!(v > 0.0) || !std::isfinite(v))
      return InvalidArgument("spec.gp.scp.", field, " = ", v, ": must be finite and > 0");
    *out = v;
    return absl::OkStatus();
  };
  NUPMPC_RETURN_IF_ERROR(optional_positive(s.penalty(), &options.penalty, "penalty"));
  NUPMPC_RETURN_IF_ERROR(
      optional_positive(s.initial_trust_radius(), &options.initial_trust_radius, "initial_trust_radius"));
  NUPMPC_RETURN_IF_ERROR(optional_positive(s.tolerance(), &options.tolerance, "tolerance"));
  // The SCP stops when its radius falls below min_trust_radius: a smaller start is no start.
  if (options.initial_trust_radius < options.min_trust_radius) {
    return InvalidArgument("spec.gp.scp.initial_trust_radius = ", s.initial_trust_radius(),
                           ": must be >= ", options.min_trust_radius, " (the radius at which the SCP stops)");
  }
  options.max_trust_radius = std::max(options.max_trust_radius, options.initial_trust_radius);
  // Every rule of the SCP options here, before the O(P³) set-up (LinGpScp::Create checks
  // them again, after it).
  if (absl::Status valid = gp::Validate(options); !valid.ok()) {
    std::string message(valid.message());
    const std::string prefix = "ScpOptions.";
    if (message.rfind(prefix, 0) == 0) message = "spec.gp.scp." + message.substr(prefix.size());
    return absl::InvalidArgumentError(message);
  }

  Eigen::VectorXd reference = Eigen::VectorXd::Zero(1);
  if (g.reference_size() > 0) {
    if (g.reference_size() != 1 && g.reference_size() != problem.horizon) {
      return InvalidArgument("spec.gp.reference: expected 1 or ", problem.horizon, " values, got ", g.reference_size());
    }
    NUPMPC_ASSIGN_OR_RETURN(reference, FiniteVector(g.reference(), "spec.gp.reference"));
  }
  const int window = training.layout.dimension();
  Eigen::VectorXd x0 = Eigen::VectorXd::Zero(window);
  if (spec.has_initial_state()) {
    if (spec.initial_state().has_covariance()) {
      return InvalidArgument("spec.initial_state.covariance: GP sessions take a measured past window (no covariance)");
    }
    if (spec.initial_state().mean_size() > 0) {
      if (spec.initial_state().mean_size() != window) {
        return InvalidArgument("spec.initial_state.mean: expected ", window,
                               " values (the past window [y[t-l..t-1], u[t-m-1..t-1]]), got ",
                               spec.initial_state().mean_size());
      }
      NUPMPC_ASSIGN_OR_RETURN(x0, FiniteVector(spec.initial_state().mean(), "spec.initial_state.mean"));
    }
  }

  // Everything above is O(P) or less and checks every rule of the spec; from here on the
  // O(P³) set-up runs (kernel fit, factorisation), stopped by the call's deadline or
  // cancellation: a stopped set-up returns DEADLINE_EXCEEDED or CANCELLED saying how far it
  // got, and nothing is cached.
  const core::Deadline stop = core::Deadline::After(fit_options.max_seconds, fit_options.cancel);
  const auto make_model = [&]() -> absl::StatusOr<gp::GpModel> {
    NUPMPC_ASSIGN_OR_RETURN(const gp::SeArdKernel kernel, KernelFor(g.model(), training, "spec.gp.model", fit_options));
    absl::StatusOr<gp::GpModel> model =
        gp::GpModel::Create(training.data.regressors, training.data.targets, kernel, stop);
    if (!model.ok())
      return absl::Status(model.status().code(), absl::StrCat("spec.gp.model: ", model.status().message()));
    return model;
  };
  std::shared_ptr<const gp::GpModel> model;
  if (cache != nullptr) {
    // The GpModel message (lags, data, kernel or none) identifies the model: a fit from the
    // default start is deterministic.
    NUPMPC_ASSIGN_OR_RETURN(model, cache->GetOrCreate(g.model().SerializeAsString(), make_model));
  } else {
    NUPMPC_ASSIGN_OR_RETURN(gp::GpModel built, make_model());
    model = std::make_shared<const gp::GpModel>(std::move(built));
  }
  // The SCP's set-up linearises the GP along a first plan: O(P²) per column when K has no
  // low-rank factor. Not started for a caller who has gone (the model stays cached).
  if (stop.Requested()) return stop.Stopped("setting up the SCP (the GP model is built)");
  NUPMPC_ASSIGN_OR_RETURN(std::unique_ptr<gp::GpMpcSession> session,
                          gp::GpMpcSession::Create(std::move(model), problem, options, reference));
  NUPMPC_RETURN_IF_ERROR(session->SetInitialState(x0));
  return session;
}

absl::Status FitGpModel(const v1::FitGpModelRequest& request, const SizeLimits& limits,
                        const gp::FitOptions& fit_limits, v1::FitGpModelResponse* response) {
  if (!request.has_model()) return InvalidArgument("model: required");
  NUPMPC_ASSIGN_OR_RETURN(const GpTrainingData training, GpTrainingDataFromProto(request.model(), "model", limits));
  gp::SeArdKernel start = DefaultKernelStart(training.data);
  if (request.model().has_kernel()) {
    NUPMPC_ASSIGN_OR_RETURN(start,
                            KernelFromProto(request.model().kernel(), training.layout.dimension(), "model.kernel"));
  }
  if (request.max_iterations() > 100000) return InvalidArgument("max_iterations: at most 100000");
  gp::FitOptions options = fit_limits;
  if (request.max_iterations() > 0) options.max_iterations = static_cast<int>(request.max_iterations());
  const auto start_time = std::chrono::steady_clock::now();
  const core::Deadline stop = core::Deadline::After(options.max_seconds, options.cancel);
  absl::StatusOr<gp::FitResult> fit =
      gp::FitHyperparameters(training.data.regressors, training.data.targets, start, options);
  if (!fit.ok()) return absl::Status(fit.status().code(), absl::StrCat("model: ", fit.status().message()));
  if (fit->stopped) return StoppedFit(*fit, options, static_cast<int>(training.data.targets.size()));
  // The training error needs the model: its O(P³) set-up stops at the same deadline.
  absl::StatusOr<gp::GpModel> model =
      gp::GpModel::Create(training.data.regressors, training.data.targets, fit->kernel, stop);
  if (!model.ok())
    return absl::Status(model.status().code(), absl::StrCat("model (fitted): ", model.status().message()));
  double squared_error = 0.0;
  const Eigen::Index points = training.data.targets.size();
  for (Eigen::Index i = 0; i < points; ++i) {
    // O(P) per point without the low-rank fast path: checked every few hundred.
    if (i % 256 == 0 && stop.Requested()) {
      return stop.Stopped(absl::StrCat("computing the training error (point ", i, " of ", points, ")"));
    }
    const double e = training.data.targets(i) - model->Mean(training.data.regressors.row(i).transpose());
    squared_error += e * e;
  }
  KernelToProto(fit->kernel, response->mutable_kernel());
  KernelToProto(start, response->mutable_initial_kernel());
  response->set_negative_log_likelihood(fit->negative_log_likelihood);
  response->set_initial_negative_log_likelihood(fit->initial_negative_log_likelihood);
  response->set_iterations(static_cast<unsigned>(fit->iterations));
  response->set_converged(fit->converged);
  response->set_gradient_norm(fit->gradient_norm);
  response->set_num_points(static_cast<unsigned>(training.data.targets.size()));
  response->set_training_rmse(std::sqrt(squared_error / static_cast<double>(training.data.targets.size())));
  response->set_fit_ms(
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_time).count());
  return absl::OkStatus();
}

}  // namespace nupmpc::server
