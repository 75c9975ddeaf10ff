#include "core/nonlinear/nonlinear_model.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

absl::Status CheckDimensions(const NonlinearModel& model, const Problem& problem) {
  if (!model.transition || !model.output) {
    return absl::InvalidArgumentError("NonlinearModel.transition/output: both functions are required");
  }
  const auto mismatch = [](const char* field, int got, int want) {
    return absl::InvalidArgumentError(
        absl::StrCat("Problem.", field, " = ", got, " does not match the nonlinear model's ", want));
  };
  if (problem.num_states != model.num_states) return mismatch("num_states", problem.num_states, model.num_states);
  if (problem.num_inputs != model.num_inputs) return mismatch("num_inputs", problem.num_inputs, model.num_inputs);
  if (problem.num_outputs != model.num_outputs) {
    return mismatch("num_outputs", problem.num_outputs, model.num_outputs);
  }
  if (problem.horizon < 1) return mismatch("horizon", problem.horizon, 1);
  const std::size_t N = problem.horizon;
  if (problem.output_priors.size() != (N + 1) * model.num_outputs) {
    return absl::InvalidArgumentError(
        absl::StrCat("Problem.output_priors: expected (N+1)·K = ", (N + 1) * model.num_outputs, " entries, got ",
                     problem.output_priors.size()));
  }
  return absl::OkStatus();
}

// One per-state (or per-input) vector of TrustRegion: empty, or `size` entries, each > 0
// (+∞ = none).
absl::Status CheckPerComponent(const Eigen::VectorXd& values, const char* field, int size, const char* component) {
  if (values.size() == 0) return absl::OkStatus();
  if (values.size() != size) {
    return absl::InvalidArgumentError(absl::StrCat("TrustRegion.", field, ": expected size ", size, " (one per ",
                                                   component, "), got ", values.size()));
  }
  for (int i = 0; i < size; ++i) {
    if (!(values(i) > 0.0)) {
      return absl::InvalidArgumentError(
          absl::StrCat("TrustRegion.", field, "[", i, "]: must be > 0 (+inf for none), got ", values(i)));
    }
  }
  return absl::OkStatus();
}

absl::Status CheckTrustRegion(const TrustRegion& trust, int M, int L) {
  NUPMPC_RETURN_IF_ERROR(CheckPerComponent(trust.state_radius, "state_radius", M, "state"));
  NUPMPC_RETURN_IF_ERROR(CheckPerComponent(trust.state_proximal_stddev, "state_proximal_stddev", M, "state"));
  return CheckPerComponent(trust.input_proximal_stddev, "input_proximal_stddev", L, "input");
}

// The components with a finite entry in `values`, with that entry.
std::vector<std::pair<int, double>> FiniteEntries(const Eigen::VectorXd& values) {
  std::vector<std::pair<int, double>> entries;
  for (int i = 0; i < values.size(); ++i) {
    if (std::isfinite(values(i))) entries.emplace_back(i, values(i));
  }
  return entries;
}

class ModelLinearisation final : public Linearisation {
 public:
  ModelLinearisation(NonlinearModel model, const Problem& problem, const TrustRegion& trust)
      : model_(std::move(model)), shape_(problem) {
    const int N = problem.horizon, M = model_.num_states, L = model_.num_inputs, K = model_.num_outputs;
    // Extra outputs after the model's: one per trusted state, then one per damped state.
    trusted_ = FiniteEntries(trust.state_radius);
    damped_ = FiniteEntries(trust.state_proximal_stddev);
    damped_inputs_ = FiniteEntries(trust.input_proximal_stddev);
    const int T = static_cast<int>(trusted_.size() + damped_.size());
    shape_.A.assign(N, Eigen::MatrixXd::Zero(M, M));
    shape_.B.assign(N, Eigen::MatrixXd::Zero(M, L));
    shape_.state_offset.assign(N, Eigen::VectorXd::Zero(M));
    shape_.num_outputs = K + T;
    shape_.C.assign(N + 1, Eigen::MatrixXd::Zero(K + T, M));
    shape_.output_offset.assign(N + 1, Eigen::VectorXd::Zero(K + T));
    shape_.output_priors.assign(static_cast<std::size_t>(N + 1) * (K + T), ScalarPrior::Free());
    CopyBase(problem, &shape_);
    for (int n = 1; n <= N; ++n) {  // x[0] is given
      int extra = K;
      for (const auto& [state, radius] : trusted_) shape_.C[n](extra++, state) = 1.0;
      for (const auto& [state, stddev] : damped_) shape_.C[n](extra++, state) = 1.0;
    }
    x_.resize(M);
    u_.resize(L);
    next_.resize(M);
    y_.resize(K);
    dhdx_.resize(K, M);
  }

  const Problem& shape() const override { return shape_; }

  // Only the point-independent fields are taken from `base`; its model fields are ignored
  // as in MakeModelLinearisation().
  absl::Status SetBase(const Problem& base) override {
    NUPMPC_RETURN_IF_ERROR(CheckDimensions(model_, base));
    if (base.horizon != shape_.horizon) {
      return absl::FailedPreconditionError(
          absl::StrCat("Problem.horizon = ", base.horizon, " does not match the linearisation's ", shape_.horizon));
    }
    if (base.terminal.has_value() != shape_.terminal.has_value()) {
      return absl::FailedPreconditionError("Problem.terminal: presence does not match the linearisation's");
    }
    // Validate the priors and x[0] in the linearised problem's shape, on a copy.
    Problem candidate = shape_;
    CopyBase(base, &candidate);
    NUPMPC_RETURN_IF_ERROR(Validate(candidate));
    shape_ = std::move(candidate);
    return absl::OkStatus();
  }

  void SetProximalScale(double scale) override { proximal_scale_ = scale; }

  void Linearise(const Solution& point, Problem* problem) const override {
    const int N = shape_.horizon;
    for (int n = 0; n <= N; ++n) {
      x_ = point.states.row(n).transpose();
      if (n < N) {
        u_ = point.inputs.row(n).transpose();
        model_.transition(n, x_, u_, &next_, &problem->A[n], &problem->B[n]);
        problem->state_offset[n] = next_ - problem->A[n] * x_ - problem->B[n] * u_;
        for (const auto& [input, unscaled] : damped_inputs_) {
          // The caller's Gaussian part (if any) times N(u*, σ²): precisions add.
          const double stddev = proximal_scale_ * unscaled;
          const ScalarPrior& base = shape_.input_prior(n, input);
          const double base_precision = base.has_gaussian() ? 1.0 / base.variance : 0.0;
          const double precision = base_precision + 1.0 / (stddev * stddev);
          const double mean = (base_precision * base.mean + u_(input) / (stddev * stddev)) / precision;
          problem->mutable_input_prior(n, input) = base.WithGaussian(mean, 1.0 / precision);
        }
      }
      auto C = problem->C[n].topRows(model_.num_outputs);
      model_.output(n, x_, &y_, &dhdx_);
      C = dhdx_;
      problem->output_offset[n].head(model_.num_outputs) = y_ - dhdx_ * x_;
      if (n == 0) continue;
      int extra = model_.num_outputs;
      for (const auto& [state, radius] : trusted_) {
        problem->mutable_output_prior(n, extra++) = ScalarPrior::Box(x_(state) - radius, x_(state) + radius);
      }
      for (const auto& [state, unscaled] : damped_) {
        const double stddev = proximal_scale_ * unscaled;
        problem->mutable_output_prior(n, extra++) = ScalarPrior::Gaussian(x_(state), stddev * stddev);
      }
    }
  }

  // The plan's dynamics defect and the gap between its (linearised) outputs and h.
  double NonlinearViolation(const Solution& plan) const override {
    const int N = shape_.horizon;
    double worst = 0.0;
    Eigen::MatrixXd A(model_.num_states, model_.num_states), B(model_.num_states, model_.num_inputs);
    Eigen::MatrixXd C(model_.num_outputs, model_.num_states);
    for (int n = 0; n <= N; ++n) {
      x_ = plan.states.row(n).transpose();
      if (n < N) {
        u_ = plan.inputs.row(n).transpose();
        model_.transition(n, x_, u_, &next_, &A, &B);
        worst = std::max(worst, (plan.states.row(n + 1).transpose() - next_).cwiseAbs().maxCoeff());
      }
      model_.output(n, x_, &y_, &C);
      worst = std::max(worst, (plan.outputs.row(n).head(model_.num_outputs).transpose() - y_).cwiseAbs().maxCoeff());
    }
    return worst;
  }

 private:
  // The point-independent fields: x[0], priors on inputs and on the model's outputs,
  // terminal cost (the trust-region outputs keep theirs).
  void CopyBase(const Problem& base, Problem* linearised) const {
    linearised->initial_mean = base.initial_mean;
    linearised->initial_covariance = base.initial_covariance;
    linearised->input_priors = base.input_priors;
    linearised->terminal = base.terminal;
    for (int n = 0; n <= base.horizon; ++n) {
      for (int k = 0; k < base.num_outputs; ++k) linearised->mutable_output_prior(n, k) = base.output_prior(n, k);
    }
  }

  NonlinearModel model_;
  std::vector<std::pair<int, double>> trusted_;        ///< (state, trust radius), in output order
  std::vector<std::pair<int, double>> damped_;         ///< (state, proximal σ), in output order
  std::vector<std::pair<int, double>> damped_inputs_;  ///< (input, proximal σ)
  double proximal_scale_ = 1.0;                        ///< set by the sequential solver's step control
  Problem shape_;
  mutable Eigen::MatrixXd dhdx_;
  mutable Eigen::VectorXd x_, u_, next_, y_;  // scratch: Linearise() allocates nothing
};

}  // namespace

absl::StatusOr<std::unique_ptr<Linearisation>> MakeModelLinearisation(NonlinearModel model, const Problem& problem,
                                                                      TrustRegion trust_region) {
  NUPMPC_RETURN_IF_ERROR(CheckDimensions(model, problem));
  NUPMPC_RETURN_IF_ERROR(CheckTrustRegion(trust_region, model.num_states, model.num_inputs));
  return std::make_unique<ModelLinearisation>(std::move(model), problem, trust_region);
}

Eigen::MatrixXd SimulateNonlinear(const NonlinearModel& model, const Eigen::VectorXd& x0,
                                  const Eigen::MatrixXd& inputs) {
  const int N = static_cast<int>(inputs.rows());
  Eigen::MatrixXd states(N + 1, model.num_states);
  Eigen::MatrixXd A(model.num_states, model.num_states), B(model.num_states, model.num_inputs);
  Eigen::VectorXd x = x0, next(model.num_states);
  states.row(0) = x.transpose();
  for (int n = 0; n < N; ++n) {
    model.transition(n, x, inputs.row(n).transpose(), &next, &A, &B);
    x = next;
    states.row(n + 1) = x.transpose();
  }
  return states;
}

double JacobianError(const NonlinearModel& model, int n, const Eigen::VectorXd& x, const Eigen::VectorXd& u) {
  const int M = model.num_states, L = model.num_inputs, K = model.num_outputs;
  Eigen::MatrixXd A(M, M), B(M, L), C(K, M), scratch_a(M, M), scratch_b(M, L), scratch_c(K, M);
  Eigen::VectorXd next(M), y(K);
  model.transition(n, x, u, &next, &A, &B);
  model.output(n, x, &y, &C);
  // The three maps as functions of one vector, for the finite differences.
  const auto f_of_x = [&](const Eigen::VectorXd& v) {
    model.transition(n, v, u, &next, &scratch_a, &scratch_b);
    return Eigen::VectorXd(next);
  };
  const auto f_of_u = [&](const Eigen::VectorXd& v) {
    model.transition(n, x, v, &next, &scratch_a, &scratch_b);
    return Eigen::VectorXd(next);
  };
  const auto h_of_x = [&](const Eigen::VectorXd& v) {
    model.output(n, v, &y, &scratch_c);
    return Eigen::VectorXd(y);
  };
  double worst = 0.0;
  const auto compare = [&](const auto& map, const Eigen::VectorXd& at, int j, const Eigen::VectorXd& analytic) {
    const double h = 1e-6 * (1.0 + std::abs(at(j)));
    Eigen::VectorXd plus = at, minus = at;
    plus(j) += h;
    minus(j) -= h;
    const Eigen::VectorXd difference = (map(plus) - map(minus)) / (2 * h);
    worst = std::max(worst, (difference - analytic).cwiseAbs().maxCoeff() / (1.0 + analytic.cwiseAbs().maxCoeff()));
  };
  for (int j = 0; j < M; ++j) {
    compare(f_of_x, x, j, A.col(j));
    compare(h_of_x, x, j, C.col(j));
  }
  for (int j = 0; j < L; ++j) compare(f_of_u, u, j, B.col(j));
  return worst;
}

}  // namespace nupmpc::core
