#include "loadtest/instances/spec_from_problem.h"

#include <algorithm>
#include <limits>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/public/status_macros.h"

namespace nupmpc::bench {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Row-major copy of a matrix.
void CopyRows(const Eigen::MatrixXd& m, google::protobuf::RepeatedField<double>* out) {
  out->Resize(static_cast<int>(m.size()), 0.0);
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(out->mutable_data(), m.rows(),
                                                                                     m.cols()) = m;
}

void SetMatrix(const Eigen::MatrixXd& m, v1::Matrix* out) {
  out->set_rows(static_cast<unsigned>(m.rows()));
  out->set_cols(static_cast<unsigned>(m.cols()));
  CopyRows(m, out->mutable_data());
}

// Per-step arrays of one component; compressed to one value when constant.
absl::Status ComponentToProto(const std::vector<core::ScalarPrior>& priors, int steps, int stride, int offset,
                              const std::string& path, v1::ComponentPrior* out) {
  // One ComponentPrior has one kind. A constraint that changes side over the horizon, or
  // is absent at some steps, is a BOX with infinite sides where needed.
  core::PriorKind kind = core::PriorKind::kNone;
  bool absent_somewhere = false, sides_mixed = false;
  for (int n = 0; n < steps; ++n) {
    const core::ScalarPrior& p = priors[static_cast<std::size_t>(n) * stride + offset];
    if (p.kind == core::PriorKind::kNone) {
      absent_somewhere = true;
    } else if (kind == core::PriorKind::kNone) {
      kind = p.kind;
    } else if (p.kind != kind) {
      const core::ScalarPrior first_kind{.kind = kind};
      if (!p.is_constraint() || !first_kind.is_constraint()) {
        return absl::InvalidArgumentError(absl::StrCat(path, ": mixes prior kinds over the horizon"));
      }
      sides_mixed = true;
    }
  }
  if (core::ScalarPrior{.kind = kind}.is_constraint() && (absent_somewhere || sides_mixed)) {
    kind = core::PriorKind::kBox;
  }
  switch (kind) {
    case core::PriorKind::kNone:
      out->set_kind(v1::PRIOR_KIND_UNSPECIFIED);
      break;
    case core::PriorKind::kL1:
      out->set_kind(v1::PRIOR_KIND_L1);
      break;
    case core::PriorKind::kHuber:
      out->set_kind(v1::PRIOR_KIND_HUBER);
      break;
    case core::PriorKind::kAtLeast:
      out->set_kind(v1::PRIOR_KIND_AT_LEAST);
      break;
    case core::PriorKind::kAtMost:
      out->set_kind(v1::PRIOR_KIND_AT_MOST);
      break;
    case core::PriorKind::kBox:
      out->set_kind(v1::PRIOR_KIND_BOX);
      break;
    case core::PriorKind::kPlainNuv:
      out->set_kind(v1::PRIOR_KIND_PLAIN_NUV);
      break;
    case core::PriorKind::kSmoothedNuv:
      out->set_kind(v1::PRIOR_KIND_SMOOTHED_NUV);
      break;
    case core::PriorKind::kLp:
      out->set_kind(v1::PRIOR_KIND_LP);
      break;
    case core::PriorKind::kBinary:
      out->set_kind(v1::PRIOR_KIND_BINARY);
      break;
  }
  const bool em = priors[static_cast<std::size_t>(offset)].em;
  for (int n = 0; n < steps; ++n) {
    const core::ScalarPrior& p = priors[static_cast<std::size_t>(n) * stride + offset];
    if (core::IsNonconvex(p.kind) && p.em != em) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": mixes EM and AM estimation over the horizon"));
    }
    out->add_weight(p.has_gaussian() ? 1.0 / p.variance : 0.0);
    out->add_target(p.has_gaussian() ? p.mean : 0.0);
    const bool lower_used = p.kind != core::PriorKind::kNone && p.kind != core::PriorKind::kAtMost;
    const bool upper_used =
        p.kind == core::PriorKind::kAtMost || p.kind == core::PriorKind::kBox || p.kind == core::PriorKind::kBinary;
    out->add_lower(lower_used ? p.lower : -kInf);
    out->add_upper(upper_used ? p.upper : kInf);
    out->add_slope(p.kind == core::PriorKind::kNone ? kInf : p.slope);
    out->add_radius(p.kind == core::PriorKind::kHuber || p.kind == core::PriorKind::kSmoothedNuv ? p.radius : 1.0);
    out->add_exponent(p.kind == core::PriorKind::kLp ? p.exponent : 1.0);
    if (core::IsNonconvex(p.kind) && !p.em) out->set_estimation(v1::ESTIMATION_AM);
  }
  // Compress constant arrays; drop arrays the kind does not use.
  const auto compress = [](google::protobuf::RepeatedField<double>* f) {
    for (int i = 1; i < f->size(); ++i) {
      if (!((*f)[i] == (*f)[0])) return;
    }
    f->Truncate(std::min(f->size(), 1));
  };
  for (auto* f : {out->mutable_weight(), out->mutable_target(), out->mutable_lower(), out->mutable_upper(),
                  out->mutable_slope(), out->mutable_radius(), out->mutable_exponent()}) {
    compress(f);
  }
  if (out->kind() == v1::PRIOR_KIND_UNSPECIFIED) {
    out->clear_lower();
    out->clear_upper();
    out->clear_slope();
  }
  if (out->kind() == v1::PRIOR_KIND_AT_LEAST) out->clear_upper();
  if (out->kind() == v1::PRIOR_KIND_AT_MOST) out->clear_lower();
  if (out->kind() != v1::PRIOR_KIND_HUBER && out->kind() != v1::PRIOR_KIND_SMOOTHED_NUV) out->clear_radius();
  if (out->kind() != v1::PRIOR_KIND_LP) out->clear_exponent();
  if (out->kind() == v1::PRIOR_KIND_PLAIN_NUV || out->kind() == v1::PRIOR_KIND_SMOOTHED_NUV ||
      out->kind() == v1::PRIOR_KIND_BINARY) {
    out->clear_slope();
  }
  return absl::OkStatus();
}
}  // namespace

absl::StatusOr<v1::ProblemSpec> SpecFromProblem(const core::Problem& p) {
  v1::ProblemSpec spec;
  v1::Model* m = spec.mutable_model();
  m->set_num_states(p.num_states);
  m->set_num_inputs(p.num_inputs);
  m->set_num_outputs(p.num_outputs);
  m->set_horizon(p.horizon);
  for (const auto& a : p.A) SetMatrix(a, m->add_a());
  for (const auto& b : p.B) SetMatrix(b, m->add_b());
  if (p.num_outputs > 0) {
    for (const auto& c : p.C) SetMatrix(c, m->add_c());
  }
  for (const auto& c : p.state_offset) m->mutable_state_offset()->Add(c.data(), c.data() + c.size());
  for (const auto& d : p.output_offset) m->mutable_output_offset()->Add(d.data(), d.data() + d.size());
  v1::InitialState* x0 = spec.mutable_initial_state();
  x0->mutable_mean()->Add(p.initial_mean.data(), p.initial_mean.data() + p.initial_mean.size());
  if (!p.initial_state_fixed()) SetMatrix(p.initial_covariance, x0->mutable_covariance());
  for (int l = 0; l < p.num_inputs; ++l) {
    NUPMPC_RETURN_IF_ERROR(ComponentToProto(p.input_priors, p.horizon, p.num_inputs, l, absl::StrCat("input ", l),
                                            spec.add_input_priors()));
  }
  for (int k = 0; k < p.num_outputs; ++k) {
    NUPMPC_RETURN_IF_ERROR(ComponentToProto(p.output_priors, p.horizon + 1, p.num_outputs, k,
                                            absl::StrCat("output ", k), spec.add_output_priors()));
  }
  if (p.terminal.has_value()) {
    v1::TerminalCost* t = spec.mutable_terminal();
    t->mutable_target()->Add(p.terminal->target.data(), p.terminal->target.data() + p.terminal->target.size());
    SetMatrix(p.terminal->weight, t->mutable_weight());
  }
  return spec;
}

}  // namespace nupmpc::bench
