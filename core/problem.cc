#include "core/problem.h"

#include <cmath>
#include <string>

#include "Eigen/Eigenvalues"
#include "absl/strings/str_cat.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {
namespace {

std::string Indexed(const char* field, int index) {
  return index < 0 ? std::string(field) : absl::StrCat(field, "[", index, "]");
}

absl::Status CheckMatrices(const std::vector<Eigen::MatrixXd>& matrices, const char* field, std::size_t per_step_count,
                           int rows, int cols) {
  if (matrices.size() != 1 && matrices.size() != per_step_count) {
    return absl::InvalidArgumentError(absl::StrCat("Problem.", field, ": expected 1 (time-invariant) or ",
                                                   per_step_count, " (per step) matrices, got ", matrices.size()));
  }
  for (std::size_t i = 0; i < matrices.size(); ++i) {
    const Eigen::MatrixXd& m = matrices[i];
    if (m.rows() != rows || m.cols() != cols) {
      return absl::InvalidArgumentError(
          absl::StrCat("Problem.", field, "[", i, "]: expected ", rows, "x", cols, ", got ", m.rows(), "x", m.cols()));
    }
    if (!m.allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat("Problem.", field, "[", i, "]: contains a non-finite number"));
    }
  }
  return absl::OkStatus();
}

absl::Status CheckOffsets(const std::vector<Eigen::VectorXd>& offsets, const char* field, std::size_t per_step_count,
                          int size) {
  if (offsets.empty()) return absl::OkStatus();
  if (offsets.size() != 1 && offsets.size() != per_step_count) {
    return absl::InvalidArgumentError(
        absl::StrCat("Problem.", field, ": expected 0, 1 or ", per_step_count, " vectors, got ", offsets.size()));
  }
  for (std::size_t i = 0; i < offsets.size(); ++i) {
    if (offsets[i].size() != size) {
      return absl::InvalidArgumentError(
          absl::StrCat("Problem.", field, "[", i, "]: expected size ", size, ", got ", offsets[i].size()));
    }
    if (!offsets[i].allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat("Problem.", field, "[", i, "]: contains a non-finite number"));
    }
  }
  return absl::OkStatus();
}

bool IsSymmetric(const Eigen::MatrixXd& m) {
  const double scale = std::max(1.0, m.cwiseAbs().maxCoeff());
  return (m - m.transpose()).cwiseAbs().maxCoeff() <= 1e-10 * scale;
}

}  // namespace

const char* PriorKindName(PriorKind kind) {
  switch (kind) {
    case PriorKind::kNone:
      return "none";
    case PriorKind::kL1:
      return "l1";
    case PriorKind::kHuber:
      return "huber";
    case PriorKind::kAtLeast:
      return "at_least";
    case PriorKind::kAtMost:
      return "at_most";
    case PriorKind::kBox:
      return "box";
    case PriorKind::kPlainNuv:
      return "plain_nuv";
    case PriorKind::kSmoothedNuv:
      return "smoothed_nuv";
    case PriorKind::kLp:
      return "lp";
    case PriorKind::kBinary:
      return "binary";
  }
  return "unknown";
}

absl::Status ValidatePrior(const ScalarPrior& p, const char* field, int index) {
  const auto bad = [&](const char* member, double value, const char* rule) {
    return absl::InvalidArgumentError(absl::StrCat(Indexed(field, index), ".", member, " = ", value, "; ", rule));
  };
  if (!std::isfinite(p.mean)) return bad("mean", p.mean, "must be finite");
  // NaN is rejected in every field, also in those the kind does not use.
  for (const auto& [member, value] :
       {std::pair{"lower", p.lower}, std::pair{"upper", p.upper}, std::pair{"slope", p.slope},
        std::pair{"radius", p.radius}, std::pair{"exponent", p.exponent},
        std::pair{"initial_variance", p.initial_variance}}) {
    if (std::isnan(value)) return bad(member, value, "must not be NaN");
  }
  if (!(p.variance > 0.0)) return bad("variance", p.variance, "must be > 0 (use +inf for no Gaussian part)");
  if (std::isnan(p.variance)) return bad("variance", p.variance, "must not be NaN");
  const bool two_sided = p.kind == PriorKind::kBox || p.kind == PriorKind::kBinary;
  const bool uses_lower = p.kind != PriorKind::kNone && p.kind != PriorKind::kAtMost;
  const bool uses_upper = p.kind == PriorKind::kAtMost || two_sided;
  if (uses_lower && !std::isfinite(p.lower)) return bad("lower", p.lower, "must be finite");
  if (uses_upper && !std::isfinite(p.upper)) return bad("upper", p.upper, "must be finite");
  if (two_sided && !(p.lower < p.upper)) {
    return absl::InvalidArgumentError(
        absl::StrCat(Indexed(field, index), ": lower = ", p.lower, " must be < upper = ", p.upper));
  }
  const bool uses_slope = p.kind != PriorKind::kNone && p.kind != PriorKind::kPlainNuv &&
                          p.kind != PriorKind::kSmoothedNuv && p.kind != PriorKind::kBinary;
  if (uses_slope) {
    if (!(p.slope > 0.0) || std::isnan(p.slope)) return bad("slope", p.slope, "must be > 0");
    const bool may_be_hard = p.is_constraint();
    if (!may_be_hard && !std::isfinite(p.slope)) {
      return bad("slope", p.slope, "must be finite for this kind (only constraints may be hard)");
    }
  }
  if ((p.kind == PriorKind::kHuber || p.kind == PriorKind::kSmoothedNuv) &&
      !(p.radius > 0.0 && std::isfinite(p.radius))) {
    return bad("radius", p.radius, "must be finite and > 0");
  }
  if (!(p.initial_variance >= 0.0) || !std::isfinite(p.initial_variance)) {
    return bad("initial_variance", p.initial_variance, "must be finite and >= 0");
  }
  if (p.kind == PriorKind::kLp && !(p.exponent > 0.0 && p.exponent <= 1.0)) {
    return bad("exponent", p.exponent, "must be in (0, 1]");
  }
  return absl::OkStatus();
}

Problem Problem::TimeInvariant(int M, int L, int K, int N) {
  Problem p;
  p.num_states = M;
  p.num_inputs = L;
  p.num_outputs = K;
  p.horizon = N;
  p.A = {Eigen::MatrixXd::Zero(M, M)};
  p.B = {Eigen::MatrixXd::Zero(M, L)};
  p.C = {Eigen::MatrixXd::Zero(K, M)};
  p.initial_mean = Eigen::VectorXd::Zero(M);
  p.input_priors.assign(static_cast<std::size_t>(N) * L, ScalarPrior::Free());
  p.output_priors.assign(static_cast<std::size_t>(N + 1) * K, ScalarPrior::Free());
  return p;
}

absl::Status ValidatePriors(const Problem& p) {
  const int L = p.num_inputs, K = p.num_outputs;
  const std::size_t N = static_cast<std::size_t>(p.horizon);
  if (p.input_priors.size() != N * L) {
    return absl::InvalidArgumentError(
        absl::StrCat("Problem.input_priors: expected N*L = ", N * L, " entries, got ", p.input_priors.size()));
  }
  if (p.output_priors.size() != (N + 1) * K) {
    return absl::InvalidArgumentError(absl::StrCat("Problem.output_priors: expected (N+1)*K = ", (N + 1) * K,
                                                   " entries, got ", p.output_priors.size()));
  }
  for (std::size_t i = 0; i < p.input_priors.size(); ++i) {
    NUPMPC_RETURN_IF_ERROR(ValidatePrior(p.input_priors[i], "Problem.input_priors", static_cast<int>(i)));
  }
  for (std::size_t i = 0; i < p.output_priors.size(); ++i) {
    NUPMPC_RETURN_IF_ERROR(ValidatePrior(p.output_priors[i], "Problem.output_priors", static_cast<int>(i)));
  }
  return CheckPriorGrouping(p);
}

absl::Status CheckPriorGrouping(const Problem& p) {
  const int L = p.num_inputs;
  for (std::size_t i = 0; i < p.output_priors.size(); ++i) {
    if (p.output_priors[i].rounds_with_next) {
      return absl::InvalidArgumentError(
          absl::StrCat("Problem.output_priors[", i, "].rounds_with_next: only binary inputs are rounded"));
    }
  }
  for (std::size_t i = 0; i < p.input_priors.size(); ++i) {
    const ScalarPrior& prior = p.input_priors[i];
    if (!prior.rounds_with_next) continue;
    const bool next_fits = (i + 1) % L != 0 && p.input_priors[i + 1].kind == PriorKind::kBinary &&
                           p.input_priors[i + 1].lower == prior.lower && p.input_priors[i + 1].upper == prior.upper;
    if (prior.kind != PriorKind::kBinary || !next_fits) {
      return absl::InvalidArgumentError(absl::StrCat(
          "Problem.input_priors[", i,
          "].rounds_with_next: must be a binary followed, at the same step, by a binary with the same levels"));
    }
  }
  return absl::OkStatus();
}

absl::Status Validate(const Problem& p) {
  const auto positive = [](const char* field, int value, int min) -> absl::Status {
    if (value < min) {
      return absl::InvalidArgumentError(absl::StrCat("Problem.", field, " = ", value, "; must be >= ", min));
    }
    return absl::OkStatus();
  };
  NUPMPC_RETURN_IF_ERROR(positive("horizon", p.horizon, 1));
  NUPMPC_RETURN_IF_ERROR(positive("num_states", p.num_states, 1));
  NUPMPC_RETURN_IF_ERROR(positive("num_inputs", p.num_inputs, 0));
  NUPMPC_RETURN_IF_ERROR(positive("num_outputs", p.num_outputs, 0));
  const int M = p.num_states, L = p.num_inputs, K = p.num_outputs;
  const std::size_t N = static_cast<std::size_t>(p.horizon);
  NUPMPC_RETURN_IF_ERROR(CheckMatrices(p.A, "A", N, M, M));
  NUPMPC_RETURN_IF_ERROR(CheckMatrices(p.B, "B", N, M, L));
  NUPMPC_RETURN_IF_ERROR(CheckMatrices(p.C, "C", N + 1, K, M));
  NUPMPC_RETURN_IF_ERROR(CheckOffsets(p.state_offset, "state_offset", N, M));
  NUPMPC_RETURN_IF_ERROR(CheckOffsets(p.output_offset, "output_offset", N + 1, K));

  if (p.initial_mean.size() != M) {
    return absl::InvalidArgumentError(
        absl::StrCat("Problem.initial_mean: expected size ", M, ", got ", p.initial_mean.size()));
  }
  if (!p.initial_mean.allFinite()) {
    return absl::InvalidArgumentError("Problem.initial_mean: contains a non-finite number");
  }
  if (p.initial_covariance.size() != 0) {
    const Eigen::MatrixXd& V0 = p.initial_covariance;
    if (V0.rows() != M || V0.cols() != M) {
      return absl::InvalidArgumentError(
          absl::StrCat("Problem.initial_covariance: expected ", M, "x", M, ", got ", V0.rows(), "x", V0.cols()));
    }
    if (!V0.allFinite()) {
      return absl::InvalidArgumentError("Problem.initial_covariance: contains a non-finite number");
    }
    if (!V0.isZero(0.0)) {
      if (!IsSymmetric(V0)) {
        return absl::InvalidArgumentError("Problem.initial_covariance: must be symmetric");
      }
      Eigen::LLT<Eigen::MatrixXd> llt(V0);
      if (llt.info() != Eigen::Success) {
        return absl::InvalidArgumentError(
            "Problem.initial_covariance: must be positive definite (or all zero for a fixed x0)");
      }
    }
  }

  NUPMPC_RETURN_IF_ERROR(ValidatePriors(p));

  if (p.terminal.has_value()) {
    const auto& t = *p.terminal;
    if (t.target.size() != M) {
      return absl::InvalidArgumentError(
          absl::StrCat("Problem.terminal.target: expected size ", M, ", got ", t.target.size()));
    }
    if (t.weight.rows() != M || t.weight.cols() != M) {
      return absl::InvalidArgumentError(absl::StrCat("Problem.terminal.weight: expected ", M, "x", M, ", got ",
                                                     t.weight.rows(), "x", t.weight.cols()));
    }
    if (!t.target.allFinite() || !t.weight.allFinite()) {
      return absl::InvalidArgumentError("Problem.terminal: contains a non-finite number");
    }
    if (!IsSymmetric(t.weight)) {
      return absl::InvalidArgumentError("Problem.terminal.weight: must be symmetric");
    }
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(t.weight, Eigen::EigenvaluesOnly);
    const double scale = std::max(1.0, eig.eigenvalues().cwiseAbs().maxCoeff());
    if (eig.eigenvalues().minCoeff() < -1e-10 * scale) {
      return absl::InvalidArgumentError("Problem.terminal.weight: must be positive semidefinite");
    }
  }
  return absl::OkStatus();
}

absl::Status CheckSameShape(const Problem& session, const Problem& update) {
  const auto mismatch = [](const char* field, std::size_t got, std::size_t want) {
    return absl::FailedPreconditionError(
        absl::StrCat("Problem.", field, " = ", got, " does not match the session's ", want));
  };
  if (update.num_states != session.num_states) return mismatch("num_states", update.num_states, session.num_states);
  if (update.num_inputs != session.num_inputs) return mismatch("num_inputs", update.num_inputs, session.num_inputs);
  if (update.num_outputs != session.num_outputs) {
    return mismatch("num_outputs", update.num_outputs, session.num_outputs);
  }
  if (update.horizon != session.horizon) return mismatch("horizon", update.horizon, session.horizon);
  if (update.A.size() != session.A.size()) return mismatch("A (number of matrices)", update.A.size(), session.A.size());
  if (update.B.size() != session.B.size()) return mismatch("B (number of matrices)", update.B.size(), session.B.size());
  if (update.C.size() != session.C.size()) return mismatch("C (number of matrices)", update.C.size(), session.C.size());
  if (update.terminal.has_value() != session.terminal.has_value()) {
    return absl::FailedPreconditionError("Problem.terminal: presence does not match the session's");
  }
  return absl::OkStatus();
}

absl::Status CheckInitialState(const Problem& session, const Eigen::VectorXd& x0) {
  if (x0.size() != session.num_states) {
    return absl::FailedPreconditionError(
        absl::StrCat("initial_state: expected size ", session.num_states, ", got ", x0.size()));
  }
  if (!x0.allFinite()) return absl::InvalidArgumentError("initial_state: contains a non-finite number");
  return absl::OkStatus();
}

}  // namespace nupmpc::core
