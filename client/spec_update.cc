#include "client/spec_update.h"

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
