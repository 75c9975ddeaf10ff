#include "server/convert/spec_conversion.h"

#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "core/public/status_macros.h"
#include "server/convert/invalid_argument.h"

namespace nupmpc::server {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::string Path(const std::string& base, const char* member) { return absl::StrCat(base, ".", member); }
std::string Path(const std::string& base, const char* member, int index) {
  return absl::StrCat(base, ".", member, "[", index, "]");
}

// Reads a per-step array: empty (default), 1 value (every step) or one per step.
class PerStep {
 public:
  static absl::StatusOr<PerStep> Make(const google::protobuf::RepeatedField<double>& values, int steps,
                                      double default_value, const std::string& path) {
    if (!values.empty() && values.size() != 1 && values.size() != steps) {
      return InvalidArgument(path, ": expected 0, 1 or ", steps, " values (one per step), got ", values.size());
    }
    for (int i = 0; i < values.size(); ++i) {
      if (std::isnan(values[i])) return InvalidArgument(path, "[", i, "]: must not be NaN");
    }
    return PerStep(&values, default_value);
  }
  double at(int n) const {
    if (values_->empty()) return default_;
    return values_->size() == 1 ? (*values_)[0] : (*values_)[n];
  }
  bool empty() const { return values_->empty(); }

 private:
  PerStep(const google::protobuf::RepeatedField<double>* values, double d) : values_(values), default_(d) {}
  const google::protobuf::RepeatedField<double>* values_;
  double default_;
};

// One ComponentPrior → `steps` scalar priors written to out[n * stride + offset].
absl::Status ComponentFromProto(const v1::ComponentPrior& c, int steps, const std::string& path,
                                std::vector<core::ScalarPrior>* out, int stride, int offset) {
  NUPMPC_ASSIGN_OR_RETURN(const PerStep weight, PerStep::Make(c.weight(), steps, 0.0, Path(path, "weight")));
  NUPMPC_ASSIGN_OR_RETURN(const PerStep target, PerStep::Make(c.target(), steps, 0.0, Path(path, "target")));
  NUPMPC_ASSIGN_OR_RETURN(const PerStep lower, PerStep::Make(c.lower(), steps, -kInf, Path(path, "lower")));
  NUPMPC_ASSIGN_OR_RETURN(const PerStep upper, PerStep::Make(c.upper(), steps, kInf, Path(path, "upper")));
  NUPMPC_ASSIGN_OR_RETURN(const PerStep slope, PerStep::Make(c.slope(), steps, kInf, Path(path, "slope")));
  NUPMPC_ASSIGN_OR_RETURN(const PerStep radius, PerStep::Make(c.radius(), steps, 1.0, Path(path, "radius")));
  NUPMPC_ASSIGN_OR_RETURN(const PerStep exponent, PerStep::Make(c.exponent(), steps, 1.0, Path(path, "exponent")));
  const v1::PriorKind kind = c.kind();
  if (!v1::PriorKind_IsValid(kind))
    return InvalidArgument(Path(path, "kind"), " = ", static_cast<int>(kind), ": unknown");
  if (!v1::Estimation_IsValid(c.estimation())) {
    return InvalidArgument(Path(path, "estimation"), " = ", static_cast<int>(c.estimation()), ": unknown");
  }
  const bool em = c.estimation() != v1::ESTIMATION_AM;
  if (kind == v1::PRIOR_KIND_BINARY && (lower.empty() || upper.empty())) {
    return InvalidArgument(path, ": BINARY needs both levels (lower and upper)");
  }
  if (kind == v1::PRIOR_KIND_LP && slope.empty()) return InvalidArgument(Path(path, "slope"), ": required for LP");
  const bool needs_lower = kind == v1::PRIOR_KIND_AT_LEAST;
  const bool needs_upper = kind == v1::PRIOR_KIND_AT_MOST;
  if (needs_lower && lower.empty()) return InvalidArgument(Path(path, "lower"), ": required for AT_LEAST");
  if (needs_upper && upper.empty()) return InvalidArgument(Path(path, "upper"), ": required for AT_MOST");
  if (kind == v1::PRIOR_KIND_BOX && lower.empty() && upper.empty()) {
    return InvalidArgument(path, ": BOX needs lower and/or upper");
  }
  const bool penalty = kind == v1::PRIOR_KIND_L1 || kind == v1::PRIOR_KIND_HUBER;
  if (penalty && slope.empty()) return InvalidArgument(Path(path, "slope"), ": required for L1 and HUBER");

  for (int n = 0; n < steps; ++n) {
    const double w = weight.at(n);
    if (!(w >= 0.0) || !std::isfinite(w)) {
      return InvalidArgument(Path(path, "weight"), " at step ", n, " = ", w, ": must be finite and >= 0");
    }
    const double t = target.at(n);
    if (!std::isfinite(t)) return InvalidArgument(Path(path, "target"), " at step ", n, " = ", t, ": must be finite");
    const double s = slope.at(n);
    if (!(s > 0.0)) return InvalidArgument(Path(path, "slope"), " at step ", n, " = ", s, ": must be > 0");
    const double a = lower.at(n), b = upper.at(n);
    core::ScalarPrior p;
    switch (kind) {
      case v1::PRIOR_KIND_L1:
      case v1::PRIOR_KIND_HUBER: {
        const double centre = lower.empty() ? 0.0 : a;
        if (!std::isfinite(centre))
          return InvalidArgument(Path(path, "lower"), " at step ", n, ": the centre must be finite");
        if (!std::isfinite(s))
          return InvalidArgument(Path(path, "slope"), " at step ", n, ": must be finite for L1/HUBER");
        if (kind == v1::PRIOR_KIND_L1) {
          p = core::ScalarPrior::L1(centre, s);
        } else {
          const double r = radius.at(n);
          if (!(r > 0.0) || !std::isfinite(r)) {
            return InvalidArgument(Path(path, "radius"), " at step ", n, " = ", r, ": must be finite and > 0");
          }
          p = core::ScalarPrior::Huber(centre, r, s);
        }
        break;
      }
      case v1::PRIOR_KIND_PLAIN_NUV:
      case v1::PRIOR_KIND_SMOOTHED_NUV:
      case v1::PRIOR_KIND_LP: {
        const double centre = lower.empty() ? 0.0 : a;
        if (!std::isfinite(centre))
          return InvalidArgument(Path(path, "lower"), " at step ", n, ": the centre must be finite");
        if (kind == v1::PRIOR_KIND_PLAIN_NUV) {
          p = core::ScalarPrior::PlainNuv(centre, em);
        } else if (kind == v1::PRIOR_KIND_SMOOTHED_NUV) {
          const double r = radius.at(n);
          if (!(r > 0.0) || !std::isfinite(r)) {
            return InvalidArgument(Path(path, "radius"), " at step ", n, " = ", r, ": must be finite and > 0");
          }
          p = core::ScalarPrior::SmoothedNuv(centre, r, em);
        } else {
          const double e = exponent.at(n);
          if (!(e > 0.0 && e <= 1.0))
            return InvalidArgument(Path(path, "exponent"), " at step ", n, " = ", e, ": must be in (0, 1]");
          if (!std::isfinite(s)) return InvalidArgument(Path(path, "slope"), " at step ", n, ": must be finite for LP");
          p = core::ScalarPrior::Lp(centre, e, s);
        }
        break;
      }
      case v1::PRIOR_KIND_BINARY:
        if (!std::isfinite(a) || !std::isfinite(b) || !(a < b)) {
          return InvalidArgument(path, " at step ", n, ": levels lower = ", a, ", upper = ", b,
                                 " must be finite with lower < upper");
        }
        p = core::ScalarPrior::Binary(a, b, em);
        break;
      case v1::PRIOR_KIND_AT_LEAST:
      case v1::PRIOR_KIND_AT_MOST:
      case v1::PRIOR_KIND_BOX: {
        // A side at ±Infinity is absent at that step; both absent leaves no constraint.
        const bool has_lower = kind != v1::PRIOR_KIND_AT_MOST && a > -kInf;
        const bool has_upper = kind != v1::PRIOR_KIND_AT_LEAST && b < kInf;
        if ((kind != v1::PRIOR_KIND_AT_MOST && a == kInf) || (kind != v1::PRIOR_KIND_AT_LEAST && b == -kInf)) {
          return InvalidArgument(path, " at step ", n, ": bounds [", a, ", ", b, "] leave no feasible value");
        }
        if (has_lower && has_upper) {
          if (!(a < b)) return InvalidArgument(path, " at step ", n, ": lower = ", a, " must be < upper = ", b);
          p = core::ScalarPrior::Box(a, b, s);
        } else if (has_lower) {
          p = core::ScalarPrior::AtLeast(a, s);
        } else if (has_upper) {
          p = core::ScalarPrior::AtMost(b, s);
        }
        break;
      }
      default:
        break;
    }
    if (w > 0.0) p = p.WithGaussian(t, 1.0 / w);
    (*out)[static_cast<std::size_t>(n) * stride + offset] = p;
  }
  return absl::OkStatus();
}

// A message of core::Validate about `Problem.x`, naming the spec's field instead (a client
// knows its spec, not the core's problem).
std::string InSpecTerms(absl::string_view core_message) {
  static constexpr std::pair<absl::string_view, absl::string_view> kFields[] = {
      {"Problem.initial_covariance", "spec.initial_state.covariance"},
      {"Problem.initial_mean", "spec.initial_state.mean"},
      {"Problem.terminal", "spec.terminal"},
  };
  for (const auto& [core_field, spec_field] : kFields) {
    if (absl::StartsWith(core_message, core_field)) {
      return absl::StrCat(spec_field, core_message.substr(core_field.size()));
    }
  }
  return absl::StrCat("spec: ", core_message);
}

}  // namespace

absl::StatusOr<Eigen::MatrixXd> MatrixFromProto(const v1::Matrix& m, int rows, int cols, const std::string& path) {
  if (static_cast<int>(m.rows()) != rows || static_cast<int>(m.cols()) != cols) {
    return InvalidArgument(path, ": expected ", rows, "x", cols, ", got ", m.rows(), "x", m.cols());
  }
  if (m.data_size() != rows * cols) {
    return InvalidArgument(path, ".data: expected ", rows * cols, " values (rows*cols, row-major), got ",
                           m.data_size());
  }
  Eigen::MatrixXd out(rows, cols);
  for (int i = 0; i < rows; ++i) {
    for (int j = 0; j < cols; ++j) {
      const double v = m.data(i * cols + j);
      if (!std::isfinite(v)) return InvalidArgument(path, ".data[", i * cols + j, "] = ", v, ": must be finite");
      out(i, j) = v;
    }
  }
  return out;
}

absl::Status CheckLimit(const char* field, long long value, long long limit) {
  if (value > limit) {
    return absl::ResourceExhaustedError(absl::StrCat(field, " = ", value, " exceeds the server limit ", limit));
  }
  return absl::OkStatus();
}

absl::Status ComponentPriorsFromProto(const v1::ComponentPrior& component, int steps, const std::string& path,
                                      std::vector<core::ScalarPrior>* out, int stride, int offset) {
  return ComponentFromProto(component, steps, path, out, stride, offset);
}

absl::StatusOr<core::Problem> ProblemFromSpec(const v1::ProblemSpec& spec, const SizeLimits& limits) {
  if (!spec.has_model()) return InvalidArgument("spec.model: required");
  const v1::Model& m = spec.model();
  const int M = static_cast<int>(m.num_states()), L = static_cast<int>(m.num_inputs());
  const int K = static_cast<int>(m.num_outputs()), N = static_cast<int>(m.horizon());
  if (m.num_states() == 0) return InvalidArgument("spec.model.num_states: must be >= 1");
  if (m.num_inputs() == 0) return InvalidArgument("spec.model.num_inputs: must be >= 1");
  if (m.horizon() == 0) return InvalidArgument("spec.model.horizon: must be >= 1");
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.model.num_states", m.num_states(), limits.max_states));
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.model.num_inputs", m.num_inputs(), limits.max_inputs));
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.model.num_outputs", m.num_outputs(), limits.max_outputs));
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec.model.horizon", m.horizon(), limits.max_horizon));
  const long long scalars = static_cast<long long>(m.a_size()) * M * M + static_cast<long long>(m.b_size()) * M * L +
                            static_cast<long long>(m.c_size()) * K * M +
                            (static_cast<long long>(N) * L + static_cast<long long>(N + 1) * K) * 8 +
                            static_cast<long long>(N + 1) * (M + L) * 4;
  NUPMPC_RETURN_IF_ERROR(CheckLimit("spec (model and prior size in scalars)", scalars, limits.max_scalars));

  core::Problem p;
  p.num_states = M;
  p.num_inputs = L;
  p.num_outputs = K;
  p.horizon = N;
  const auto read_matrices = [&](const auto& list, const char* name, int rows, int cols, int per_step_count,
                                 std::vector<Eigen::MatrixXd>* out) -> absl::Status {
    if (list.size() != 1 && list.size() != per_step_count) {
      return InvalidArgument("spec.model.", name, ": expected 1 (time-invariant) or ", per_step_count,
                             " (per step) matrices, got ", list.size());
    }
    for (int i = 0; i < list.size(); ++i) {
      NUPMPC_ASSIGN_OR_RETURN(Eigen::MatrixXd mat, MatrixFromProto(list[i], rows, cols, Path("spec.model", name, i)));
      out->push_back(std::move(mat));
    }
    return absl::OkStatus();
  };
  NUPMPC_RETURN_IF_ERROR(read_matrices(m.a(), "a", M, M, N, &p.A));
  NUPMPC_RETURN_IF_ERROR(read_matrices(m.b(), "b", M, L, N, &p.B));
  if (K == 0 && m.c_size() == 0) {
    p.C.push_back(Eigen::MatrixXd::Zero(0, M));
  } else {
    NUPMPC_RETURN_IF_ERROR(read_matrices(m.c(), "c", K, M, N + 1, &p.C));
  }
  const auto read_offsets = [&](const auto& values, const char* name, int size, int steps,
                                std::vector<Eigen::VectorXd>* out) -> absl::Status {
    if (values.empty()) return absl::OkStatus();
    if (values.size() != size && values.size() != size * steps) {
      return InvalidArgument("spec.model.", name, ": expected 0, ", size, " or ", size * steps, " values, got ",
                             values.size());
    }
    for (int i = 0; i < values.size(); ++i) {
      if (!std::isfinite(values[i]))
        return InvalidArgument("spec.model.", name, "[", i, "] = ", values[i], ": must be finite");
    }
    for (int s = 0; s * size < values.size(); ++s) {
      out->push_back(Eigen::Map<const Eigen::VectorXd>(values.data() + s * size, size));
    }
    return absl::OkStatus();
  };
  NUPMPC_RETURN_IF_ERROR(read_offsets(m.state_offset(), "state_offset", M, N, &p.state_offset));
  if (K > 0) NUPMPC_RETURN_IF_ERROR(read_offsets(m.output_offset(), "output_offset", K, N + 1, &p.output_offset));

  const v1::InitialState& x0 = spec.initial_state();
  if (x0.mean_size() != M) {
    return InvalidArgument("spec.initial_state.mean: expected ", M, " values (num_states), got ", x0.mean_size());
  }
  p.initial_mean = Eigen::Map<const Eigen::VectorXd>(x0.mean().data(), M);
  if (!p.initial_mean.allFinite()) return InvalidArgument("spec.initial_state.mean: must be finite");
  if (x0.has_covariance()) {
    NUPMPC_ASSIGN_OR_RETURN(p.initial_covariance,
                            MatrixFromProto(x0.covariance(), M, M, "spec.initial_state.covariance"));
  }

  if (spec.input_priors_size() != L) {
    return InvalidArgument("spec.input_priors: expected ", L, " entries (num_inputs), got ", spec.input_priors_size());
  }
  if (spec.output_priors_size() != K) {
    return InvalidArgument("spec.output_priors: expected ", K, " entries (num_outputs), got ",
                           spec.output_priors_size());
  }
  p.input_priors.assign(static_cast<std::size_t>(N) * L, core::ScalarPrior::Free());
  p.output_priors.assign(static_cast<std::size_t>(N + 1) * K, core::ScalarPrior::Free());
  for (int l = 0; l < L; ++l) {
    NUPMPC_RETURN_IF_ERROR(
        ComponentFromProto(spec.input_priors(l), N, Path("spec", "input_priors", l), &p.input_priors, L, l));
  }
  for (int k = 0; k < K; ++k) {
    NUPMPC_RETURN_IF_ERROR(
        ComponentFromProto(spec.output_priors(k), N + 1, Path("spec", "output_priors", k), &p.output_priors, K, k));
  }
  if (spec.has_terminal()) {
    const v1::TerminalCost& t = spec.terminal();
    if (t.target_size() != M)
      return InvalidArgument("spec.terminal.target: expected ", M, " values, got ", t.target_size());
    core::Problem::Terminal terminal;
    terminal.target = Eigen::Map<const Eigen::VectorXd>(t.target().data(), M);
    if (!terminal.target.allFinite()) return InvalidArgument("spec.terminal.target: must be finite");
    NUPMPC_ASSIGN_OR_RETURN(terminal.weight, MatrixFromProto(t.weight(), M, M, "spec.terminal.weight"));
    if (!terminal.weight.isApprox(terminal.weight.transpose(), 1e-12)) {
      return InvalidArgument("spec.terminal.weight: must be symmetric");
    }
    p.terminal = std::move(terminal);
  }
  // The core's own checks (covariance definiteness, ...) as the last line.
  absl::Status core_check = core::Validate(p);
  if (!core_check.ok()) return InvalidArgument(InSpecTerms(core_check.message()));
  return p;
}

absl::StatusOr<core::SolverOptions> OptionsFromSpec(const v1::SolverOptions& o, const SizeLimits& limits) {
  core::SolverOptions out;
  switch (o.algorithm()) {
    case v1::ALGORITHM_UNSPECIFIED:
      out.algorithm = core::Algorithm::kAuto;
      break;
    case v1::ALGORITHM_IAKE:
      out.algorithm = core::Algorithm::kIake;
      break;
    case v1::ALGORITHM_IBFFD:
      out.algorithm = core::Algorithm::kIbffd;
      break;
    case v1::ALGORITHM_IFFBDD:
      out.algorithm = core::Algorithm::kIffbdd;
      break;
    default:
      return InvalidArgument("spec.options.algorithm = ", static_cast<int>(o.algorithm()), ": unknown");
  }
  if (o.max_iterations() > static_cast<unsigned>(limits.max_iterations)) {
    return absl::ResourceExhaustedError(absl::StrCat("spec.options.max_iterations = ", o.max_iterations(),
                                                     " exceeds the server limit ", limits.max_iterations));
  }
  if (o.max_iterations() > 0) out.max_iterations = static_cast<int>(o.max_iterations());
  const auto positive_or_zero = [](double v, const char* field) -> absl::Status {
    if (!(v >= 0.0) || !std::isfinite(v))
      return InvalidArgument("spec.options.", field, " = ", v, ": must be finite and >= 0");
    return absl::OkStatus();
  };
  NUPMPC_RETURN_IF_ERROR(positive_or_zero(o.objective_tolerance(), "objective_tolerance"));
  NUPMPC_RETURN_IF_ERROR(positive_or_zero(o.violation_tolerance(), "violation_tolerance"));
  NUPMPC_RETURN_IF_ERROR(positive_or_zero(o.time_limit_ms(), "time_limit_ms"));
  if (o.objective_tolerance() > 0) out.objective_tolerance = o.objective_tolerance();
  if (o.violation_tolerance() > 0) out.violation_tolerance = o.violation_tolerance();
  NUPMPC_RETURN_IF_ERROR(positive_or_zero(o.elastic_slope(), "elastic_slope"));
  out.elastic_slope = o.elastic_slope();
  if (o.elastic_after_iterations() > static_cast<unsigned>(limits.max_iterations)) {
    return InvalidArgument("spec.options.elastic_after_iterations = ", o.elastic_after_iterations(),
                           ": must not exceed the server's iteration limit ", limits.max_iterations);
  }
  if (o.elastic_after_iterations() > 0) out.elastic_after_iterations = static_cast<int>(o.elastic_after_iterations());
  NUPMPC_RETURN_IF_ERROR(core::Validate(out));
  return out;
}

}  // namespace nupmpc::server
