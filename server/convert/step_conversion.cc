#include "server/convert/step_conversion.h"

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "core/public/status_macros.h"
#include "server/convert/spec_conversion.h"

namespace nupmpc::server {
namespace {

Eigen::VectorXd ToVector(const google::protobuf::RepeatedField<double>& values) {
  return Eigen::Map<const Eigen::VectorXd>(values.data(), values.size());
}

absl::StatusOr<std::vector<core::ComponentPriors>> ComponentsFromProto(
    const google::protobuf::RepeatedPtrField<v1::PriorUpdate::Entry>& entries, int steps, const char* field) {
  std::vector<core::ComponentPriors> components(entries.size());
  for (int i = 0; i < entries.size(); ++i) {
    const v1::PriorUpdate::Entry& entry = entries[i];
    components[i].index = entry.index();  // as sent: the session's check names it
    components[i].priors.resize(steps);
    NUPMPC_RETURN_IF_ERROR(ComponentPriorsFromProto(entry.prior(), steps,
                                                    absl::StrCat("step.update.", field, "[", i, "].prior"),
                                                    &components[i].priors, /*stride=*/1, /*offset=*/0));
  }
  return components;
}

// The matrix as given (its size is the session's to check), once its data matches it.
absl::StatusOr<Eigen::MatrixXd> GivenMatrix(const v1::Matrix& m, const std::string& path) {
  // Larger than any session's matrices (which the session checks), and than an int.
  constexpr std::uint32_t kLargest = 1u << 20;
  if (m.rows() > kLargest || m.cols() > kLargest) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": ", m.rows(), "x", m.cols(), " is larger than any session's matrices"));
  }
  if (static_cast<std::uint64_t>(m.rows()) * m.cols() != static_cast<std::uint64_t>(m.data_size())) {
    return absl::InvalidArgumentError(absl::StrCat(path, ".data: expected ",
                                                   static_cast<std::uint64_t>(m.rows()) * m.cols(),
                                                   " values (rows*cols, row-major), got ", m.data_size()));
  }
  return MatrixFromProto(m, static_cast<int>(m.rows()), static_cast<int>(m.cols()), path);
}

absl::StatusOr<std::vector<core::ModelChanges::At<Eigen::MatrixXd>>> MatricesFromProto(
    const google::protobuf::RepeatedPtrField<v1::ModelUpdate::MatrixAt>& entries, const char* field) {
  std::vector<core::ModelChanges::At<Eigen::MatrixXd>> out(entries.size());
  for (int i = 0; i < entries.size(); ++i) {
    out[i].step = entries[i].step();  // as sent: the session's check names it
    NUPMPC_ASSIGN_OR_RETURN(out[i].value,
                            GivenMatrix(entries[i].matrix(), absl::StrCat("step.model.", field, "[", i, "].matrix")));
  }
  return out;
}

std::vector<core::ModelChanges::At<Eigen::VectorXd>> VectorsFromProto(
    const google::protobuf::RepeatedPtrField<v1::ModelUpdate::VectorAt>& entries) {
  std::vector<core::ModelChanges::At<Eigen::VectorXd>> out(entries.size());
  for (int i = 0; i < entries.size(); ++i) {
    out[i].step = entries[i].step();
    out[i].value = ToVector(entries[i].values());
  }
  return out;
}

absl::StatusOr<core::ModelChanges> ModelChangesFromProto(const v1::ModelUpdate& m) {
  core::ModelChanges changes;
  changes.shift = m.shift();
  if (m.state_offsets_size() > 0) changes.state_offsets = ToVector(m.state_offsets());
  if (m.output_offsets_size() > 0) changes.output_offsets = ToVector(m.output_offsets());
  NUPMPC_ASSIGN_OR_RETURN(changes.A, MatricesFromProto(m.a(), "a"));
  NUPMPC_ASSIGN_OR_RETURN(changes.B, MatricesFromProto(m.b(), "b"));
  NUPMPC_ASSIGN_OR_RETURN(changes.C, MatricesFromProto(m.c(), "c"));
  changes.state_offset = VectorsFromProto(m.state_offset());
  changes.output_offset = VectorsFromProto(m.output_offset());
  return changes;
}

}  // namespace

absl::StatusOr<core::StepUpdate> StepUpdateFromProto(const v1::Step& step, const core::Dimensions& dimensions) {
  if (!v1::WarmStart_IsValid(step.warm_start())) {
    return absl::InvalidArgumentError(
        absl::StrCat("step.warm_start = ", static_cast<int>(step.warm_start()), ": unknown"));
  }
  if (!(step.time_limit_ms() >= 0.0) || !std::isfinite(step.time_limit_ms())) {
    return absl::InvalidArgumentError(
        absl::StrCat("step.time_limit_ms = ", step.time_limit_ms(), ": must be finite and >= 0"));
  }
  if (!(step.budget_ms() >= 0.0) || !std::isfinite(step.budget_ms())) {
    return absl::InvalidArgumentError(absl::StrCat("step.budget_ms = ", step.budget_ms(), ": must be finite and >= 0"));
  }
  if (step.max_iterations() > static_cast<unsigned>(std::numeric_limits<int>::max())) {
    return absl::InvalidArgumentError("step.max_iterations: too large");
  }
  core::StepUpdate update;
  if (step.state_size() > 0) update.state = ToVector(step.state());
  if (step.previous_input_size() > 0) update.previous_input = ToVector(step.previous_input());
  if (step.reference_size() > 0) update.reference = ToVector(step.reference());
  if (step.has_model()) {
    NUPMPC_ASSIGN_OR_RETURN(update.model, ModelChangesFromProto(step.model()));
  }
  if (step.has_update()) {
    const v1::PriorUpdate& u = step.update();
    update.shift = u.shift();
    NUPMPC_ASSIGN_OR_RETURN(update.inputs, ComponentsFromProto(u.inputs(), dimensions.horizon, "inputs"));
    NUPMPC_ASSIGN_OR_RETURN(update.outputs, ComponentsFromProto(u.outputs(), dimensions.horizon + 1, "outputs"));
  }
  return update;
}

void ApplyWarmStart(v1::WarmStart warm_start, core::MpcSession& session, core::SolveLimits* limits) {
  switch (warm_start) {
    case v1::WARM_START_UNSPECIFIED:
    case v1::WARM_START_SHIFT:
      session.ShiftWarmStart();
      break;
    case v1::WARM_START_KEEP:
      break;
    case v1::WARM_START_COLD:
      limits->warm_start = false;
      break;
    default:
      break;
  }
}

absl::Status AsStepError(const absl::Status& status) {
  if (status.ok()) return status;
  const absl::string_view message = status.message();
  for (absl::string_view field : {"state", "update", "previous_input", "reference", "model"}) {
    if (absl::StartsWith(message, field)) return absl::Status(status.code(), absl::StrCat("step.", message));
  }
  return absl::Status(status.code(), absl::StrCat("step: ", message));
}

}  // namespace nupmpc::server
