#include "client/spec_update.h"

#include <cstdint>

namespace nupmpc {
namespace {

// The server stores every per-step prior expanded to one entry per step; shifting that
// (n+1 → n, last kept) is, on the spec's arrays, the same move, and a no-op on a length-1
// (constant) array.
void ShiftArray(google::protobuf::RepeatedField<double>* values) {
  for (int n = 0; n + 1 < values->size(); ++n) values->Set(n, values->Get(n + 1));
}

void ShiftComponents(google::protobuf::RepeatedPtrField<v1::ComponentPrior>* components) {
  for (v1::ComponentPrior& c : *components) {
    for (auto* f : {c.mutable_weight(), c.mutable_target(), c.mutable_lower(), c.mutable_upper(), c.mutable_slope(),
                    c.mutable_radius(), c.mutable_exponent()}) {
      ShiftArray(f);
    }
  }
}

void ReplaceComponents(const google::protobuf::RepeatedPtrField<v1::PriorUpdate::Entry>& entries,
                       google::protobuf::RepeatedPtrField<v1::ComponentPrior>* components) {
  for (const v1::PriorUpdate::Entry& e : entries) {
    // The server refuses a step with an index out of range, so an accepted one has none.
    if (e.index() < static_cast<unsigned>(components->size())) *components->Mutable(e.index()) = e.prior();
  }
}

// The model terms (Step.model), as core/session/model_update.cc writes them on the server:
// the shift, then the all-step offsets, then single steps; a term given for one step is
// stored per step from then on.
template <typename T>
void ShiftRepeated(google::protobuf::RepeatedPtrField<T>* terms) {
  for (int n = 0; n + 1 < terms->size(); ++n) terms->Mutable(n)->CopyFrom(terms->Get(n + 1));
}

// Step n+1's `width` values become step n's (the last step kept), for a per-step array.
void ShiftRows(int width, int steps, google::protobuf::RepeatedField<double>* values) {
  if (width <= 0 || values->size() != width * steps) return;
  for (int i = 0; i + width < values->size(); ++i) values->Set(i, values->Get(i + width));
}

void WriteAllSteps(const google::protobuf::RepeatedField<double>& given, int width, int steps,
                   google::protobuf::RepeatedField<double>* values) {
  if (given.empty()) return;
  if (given.size() == width && values->size() == width * steps) {
    for (int i = 0; i < values->size(); ++i) values->Set(i, given.Get(i % width));  // kept per step
  } else {
    *values = given;
  }
}

void WriteMatrices(const google::protobuf::RepeatedPtrField<v1::ModelUpdate::MatrixAt>& entries, int steps, int rows,
                   int cols, google::protobuf::RepeatedPtrField<v1::Matrix>* matrices) {
  if (entries.empty()) return;
  if (matrices->size() != steps) {
    // Stored once until now (or absent, zero: C of a model without outputs).
    v1::Matrix first;
    if (matrices->empty()) {
      first.set_rows(static_cast<std::uint32_t>(rows));
      first.set_cols(static_cast<std::uint32_t>(cols));
      first.mutable_data()->Resize(rows * cols, 0.0);
    } else {
      first = matrices->Get(0);
    }
    matrices->Clear();
    for (int n = 0; n < steps; ++n) *matrices->Add() = first;
  }
  for (const v1::ModelUpdate::MatrixAt& e : entries) *matrices->Mutable(static_cast<int>(e.step())) = e.matrix();
}

void WriteVectors(const google::protobuf::RepeatedPtrField<v1::ModelUpdate::VectorAt>& entries, int width, int steps,
                  google::protobuf::RepeatedField<double>* values) {
  if (entries.empty()) return;
  if (values->size() != width * steps) {
    // Constant (width values) or absent (zero) until now: every step gets that value.
    const google::protobuf::RepeatedField<double> constant = *values;
    values->Clear();
    for (int i = 0; i < width * steps; ++i) values->Add(constant.empty() ? 0.0 : constant.Get(i % width));
  }
  for (const v1::ModelUpdate::VectorAt& e : entries) {
    for (int i = 0; i < width; ++i) values->Set(static_cast<int>(e.step()) * width + i, e.values(i));
  }
}

void ApplyModelUpdate(const v1::ModelUpdate& update, v1::Model* model) {
  const int M = static_cast<int>(model->num_states()), K = static_cast<int>(model->num_outputs());
  const int N = static_cast<int>(model->horizon());
  if (update.shift()) {
    ShiftRepeated(model->mutable_a());
    ShiftRepeated(model->mutable_b());
    ShiftRepeated(model->mutable_c());
    ShiftRows(M, N, model->mutable_state_offset());
    ShiftRows(K, N + 1, model->mutable_output_offset());
  }
  WriteAllSteps(update.state_offsets(), M, N, model->mutable_state_offset());
  WriteAllSteps(update.output_offsets(), K, N + 1, model->mutable_output_offset());
  const int L = static_cast<int>(model->num_inputs());
  WriteMatrices(update.a(), N, M, M, model->mutable_a());
  WriteMatrices(update.b(), N, M, L, model->mutable_b());
  WriteMatrices(update.c(), N + 1, K, M, model->mutable_c());
  WriteVectors(update.state_offset(), M, N, model->mutable_state_offset());
  WriteVectors(update.output_offset(), K, N + 1, model->mutable_output_offset());
}

}  // namespace

void ApplyStepToSpec(const v1::Step& step, const v1::SolveResult& result, v1::ProblemSpec* spec) {
  if (result.status() == v1::SOLVE_STATUS_SUPERSEDED) return;
  if (step.state_size() > 0) *spec->mutable_initial_state()->mutable_mean() = step.state();
  if (spec->has_gp()) {
    // A GP session refuses step.update; its reference is replaced as a whole.
    if (step.reference_size() > 0) *spec->mutable_gp()->mutable_reference() = step.reference();
    return;
  }
  if (step.has_update()) {
    const v1::PriorUpdate& update = step.update();
    if (update.shift()) {
      ShiftComponents(spec->mutable_input_priors());
      ShiftComponents(spec->mutable_output_priors());
      // Δu sessions: the difference priors are the server's input priors, shifted with them.
      if (spec->has_input_differences()) ShiftComponents(spec->mutable_input_differences()->mutable_priors());
    }
    ReplaceComponents(update.inputs(), spec->mutable_input_priors());
    ReplaceComponents(update.outputs(), spec->mutable_output_priors());
  }
  // Accepted only by sessions that take it (the server checked every entry).
  if (step.has_model()) ApplyModelUpdate(step.model(), spec->mutable_model());
  // Δu sessions: the server carries the plan's u[0] as u[-1] of the next step (the
  // input the client is expected to apply); a step's own previous_input is for that
  // step only, and a result without a plan leaves the carried one as it was.
  const int L = static_cast<int>(spec->model().num_inputs());
  if (spec->has_input_differences() && result.has_plan() && result.inputs_size() >= L) {
    auto* previous = spec->mutable_input_differences()->mutable_previous_input();
    previous->Clear();
    previous->Add(result.inputs().begin(), result.inputs().begin() + L);
  }
}

}  // namespace nupmpc
