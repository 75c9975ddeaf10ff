#include "server/input_transform.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/model/input_differences.h"
#include "core/util/status_macros.h"

namespace nupmpc::server {
namespace {

absl::Status Invalid(const std::string& field, const std::string& rule) {
  return absl::InvalidArgumentError(absl::StrCat(field, ": ", rule));
}

// The spec's level entries as one InputLevels per input (count 0: ordinary input).
absl::StatusOr<std::vector<core::InputLevels>> LevelsFromSpec(const v1::ProblemSpec& spec, int L) {
  std::vector<core::InputLevels> levels(L);
  for (int i = 0; i < spec.input_levels_size(); ++i) {
    const v1::InputLevels& e = spec.input_levels(i);
    const std::string field = absl::StrCat("spec.input_levels[", i, "]");
    if (e.input() >= static_cast<unsigned>(L)) {
      return Invalid(field + ".input", absl::StrCat(e.input(), " must be < num_inputs = ", L));
    }
    core::InputLevels& v = levels[e.input()];
    if (v.count != 0) return Invalid(field + ".input", absl::StrCat("input ", e.input(), " is listed twice"));
    if (e.count() < 2) return Invalid(field + ".count", "must be >= 2");
    if (!std::isfinite(e.lowest())) return Invalid(field + ".lowest", "must be finite");
    if (!(e.spacing() > 0.0) || !std::isfinite(e.spacing())) return Invalid(field + ".spacing", "must be finite and > 0");
    const v1::ComponentPrior& own = spec.input_priors(static_cast<int>(e.input()));
    bool weighted = false;
    for (double w : own.weight()) weighted |= w != 0.0;
    if (own.kind() != v1::PRIOR_KIND_UNSPECIFIED || weighted) {
      return Invalid(absl::StrCat("spec.input_priors[", e.input(), "]"),
                     "a multi-level input takes no prior of its own (costs go on outputs)");
    }
    v = {.count = static_cast<int>(e.count()), .lowest = e.lowest(), .spacing = e.spacing()};
  }
  return levels;
}

}  // namespace

absl::Status ReadInputVector(const google::protobuf::RepeatedField<double>& values, int size, const std::string& field,
                              absl::StatusCode size_error, Eigen::VectorXd* out) {
  if (values.size() != size) {
    return absl::Status(size_error, absl::StrCat(field, ": expected ", size, " values (num_inputs), got ", values.size()));
  }
  for (int i = 0; i < size; ++i) {
    if (!std::isfinite(values[i])) return Invalid(absl::StrCat(field, "[", i, "]"), "must be finite");
  }
  *out = Eigen::Map<const Eigen::VectorXd>(values.data(), size);
  return absl::OkStatus();
}

void InputTransform::WriteCoreInitialState(const Eigen::VectorXd* measured, const Eigen::VectorXd& previous,
                                           Eigen::VectorXd* core_x0) const {
  if (measured != nullptr) core_x0->head(num_states) = *measured;
  core_x0->tail(num_inputs) = previous;
}

void InputTransform::MapBack(const Eigen::VectorXd& previous, core::Solution* s) const {
  if (!active()) return;
  // Rows are steps: the core's inputs are N × L' (binaries or differences).
  if (differences) {
    s->inputs = core::InputsFromDifferences(s->inputs, previous);
  } else {
    s->inputs = core::InputsFromLevels(s->inputs, levels);
  }
  s->outputs = s->outputs.leftCols(num_outputs).eval();
  s->states = s->states.leftCols(num_states).eval();
}

void InputTransform::RememberApplied(const core::Solution& mapped) {
  if (differences && mapped.inputs.rows() > 0) previous_input = mapped.inputs.row(0).transpose();
}

absl::StatusOr<core::Problem> TransformProblem(const v1::ProblemSpec& spec, core::Problem base,
                                               InputTransform* t) {
  const int M = base.num_states, L = base.num_inputs, N = base.horizon;
  *t = InputTransform{};
  t->num_states = M;
  t->num_inputs = L;
  t->num_outputs = base.num_outputs;
  const bool has_levels = spec.input_levels_size() > 0;
  t->differences = spec.has_input_differences();
  if (has_levels && t->differences) {
    return Invalid("spec.input_differences", "cannot be combined with input_levels yet");
  }
  if (has_levels) {
    NUPMPC_ASSIGN_OR_RETURN(t->levels, LevelsFromSpec(spec, L));
    absl::StatusOr<core::Problem> expanded = core::ExpandMultiLevelInputs(base, t->levels);
    if (!expanded.ok()) return Invalid("spec.input_levels", std::string(expanded.status().message()));
    return expanded;
  }
  if (!t->differences) return base;

  const v1::InputDifferences& d = spec.input_differences();
  if (d.priors_size() != L) {
    return Invalid("spec.input_differences.priors", absl::StrCat("expected ", L, " entries (num_inputs), got ",
                                                                  d.priors_size()));
  }
  std::vector<core::ScalarPrior> delta(static_cast<std::size_t>(N) * L);
  for (int l = 0; l < L; ++l) {
    NUPMPC_RETURN_IF_ERROR(ComponentPriorsFromProto(d.priors(l), N,
                                                    absl::StrCat("spec.input_differences.priors[", l, "]"), &delta,
                                                    L, l));
  }
  t->previous_input = Eigen::VectorXd::Zero(L);
  if (d.previous_input_size() != 0) {
    NUPMPC_RETURN_IF_ERROR(ReadInputVector(d.previous_input(), L, "spec.input_differences.previous_input",
                                            absl::StatusCode::kInvalidArgument, &t->previous_input));
  }
  absl::StatusOr<core::Problem> augmented = core::AugmentWithInputDifferences(base, delta, t->previous_input);
  if (!augmented.ok()) {
    return absl::Status(augmented.status().code(), absl::StrCat("spec.", augmented.status().message()));
  }
  return augmented;
}

}  // namespace nupmpc::server
