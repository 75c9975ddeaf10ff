// ApplyStepToSpec (client/spec_update.h) on specs alone: shifts of per-step and constant
// arrays, entries after the shift, GP references of length 1 and H, Δu's carried input,
// and what a superseded step leaves. tests/server/service/reconnect_fidelity_test.cc checks the
// same semantics against the server.
#include "client/spec_update.h"

#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace nupmpc {
namespace {

using ::testing::ElementsAre;

constexpr int kN = 4;

std::vector<double> Values(const google::protobuf::RepeatedField<double>& f) { return {f.begin(), f.end()}; }

void Set(const std::vector<double>& values, google::protobuf::RepeatedField<double>* field) {
  field->Clear();
  field->Add(values.begin(), values.end());
}

// Two inputs, one output, horizon kN; input 0 per-step, input 1 constant.
v1::ProblemSpec Spec() {
  v1::ProblemSpec spec;
  spec.mutable_model()->set_num_states(2);
  spec.mutable_model()->set_num_inputs(2);
  spec.mutable_model()->set_num_outputs(1);
  spec.mutable_model()->set_horizon(kN);
  Set({1.0, 2.0}, spec.mutable_initial_state()->mutable_mean());
  v1::ComponentPrior* u0 = spec.add_input_priors();
  u0->set_kind(v1::PRIOR_KIND_BOX);
  Set({0.0, 1.0, 2.0, 3.0}, u0->mutable_upper());
  Set({-1.0}, u0->mutable_lower());
  Set({5.0}, u0->mutable_weight());
  v1::ComponentPrior* u1 = spec.add_input_priors();
  Set({7.0}, u1->mutable_target());
  v1::ComponentPrior* y = spec.add_output_priors();
  Set({10.0, 11.0, 12.0, 13.0, 14.0}, y->mutable_target());
  return spec;
}

v1::SolveResult Plan(std::vector<double> inputs) {
  v1::SolveResult r;
  r.set_status(v1::SOLVE_STATUS_CONVERGED);
  r.set_has_plan(true);
  Set(inputs, r.mutable_inputs());
  return r;
}

TEST(SpecUpdateTest, ShiftMovesPerStepArraysAndKeepsConstantOnes) {
  v1::ProblemSpec spec = Spec();
  v1::Step step;
  step.mutable_update()->set_shift(true);
  ApplyStepToSpec(step, Plan({0.0, 0.0}), &spec);
  EXPECT_THAT(Values(spec.input_priors(0).upper()), ElementsAre(1.0, 2.0, 3.0, 3.0));  // last repeated
  EXPECT_THAT(Values(spec.input_priors(0).lower()), ElementsAre(-1.0));
  EXPECT_THAT(Values(spec.input_priors(0).weight()), ElementsAre(5.0));
  EXPECT_THAT(Values(spec.input_priors(1).target()), ElementsAre(7.0));
  EXPECT_THAT(Values(spec.output_priors(0).target()), ElementsAre(11.0, 12.0, 13.0, 14.0, 14.0));  // N+1 steps
  EXPECT_THAT(Values(spec.initial_state().mean()), ElementsAre(1.0, 2.0));                         // no state: kept
}

TEST(SpecUpdateTest, EntriesReplaceAfterTheShiftSoAConstantPriorBecomesPerStepUnshifted) {
  v1::ProblemSpec spec = Spec();
  v1::Step step;
  step.add_state(3.0);
  step.add_state(4.0);
  step.mutable_update()->set_shift(true);
  v1::PriorUpdate::Entry* e = step.mutable_update()->add_inputs();
  e->set_index(1);
  Set({0.5, 0.6, 0.7, 0.8}, e->mutable_prior()->mutable_target());
  ApplyStepToSpec(step, Plan({0.0, 0.0}), &spec);
  EXPECT_THAT(Values(spec.input_priors(1).target()), ElementsAre(0.5, 0.6, 0.7, 0.8));
  EXPECT_THAT(Values(spec.input_priors(0).upper()), ElementsAre(1.0, 2.0, 3.0, 3.0));  // shifted, not replaced
  EXPECT_THAT(Values(spec.initial_state().mean()), ElementsAre(3.0, 4.0));

  v1::Step next;
  next.mutable_update()->set_shift(true);
  ApplyStepToSpec(next, Plan({0.0, 0.0}), &spec);
  EXPECT_THAT(Values(spec.input_priors(1).target()), ElementsAre(0.6, 0.7, 0.8, 0.8));
}

TEST(SpecUpdateTest, GpReferenceOfLengthOneOrHReplacesTheWholeReference) {
  v1::ProblemSpec spec;
  spec.mutable_gp()->set_horizon(3);
  spec.mutable_gp()->add_reference(0.5);
  v1::Step step;
  Set({0.1, 0.2, 0.3}, step.mutable_reference());
  step.add_state(-0.1);
  step.add_state(0.2);
  ApplyStepToSpec(step, Plan({0.0, 0.0, 0.0}), &spec);
  EXPECT_THAT(Values(spec.gp().reference()), ElementsAre(0.1, 0.2, 0.3));
  EXPECT_THAT(Values(spec.initial_state().mean()), ElementsAre(-0.1, 0.2));

  v1::Step keep;  // no reference: kept
  ApplyStepToSpec(keep, Plan({0.0, 0.0, 0.0}), &spec);
  EXPECT_THAT(Values(spec.gp().reference()), ElementsAre(0.1, 0.2, 0.3));

  v1::Step constant;
  constant.add_reference(-0.2);
  ApplyStepToSpec(constant, Plan({0.0, 0.0, 0.0}), &spec);
  EXPECT_THAT(Values(spec.gp().reference()), ElementsAre(-0.2));
}

TEST(SpecUpdateTest, DifferenceSessionsCarryThePlansFirstInputAndShiftTheirRatePriors) {
  v1::ProblemSpec spec = Spec();
  v1::InputDifferences* d = spec.mutable_input_differences();
  Set({0.1, 0.2}, d->mutable_previous_input());
  Set({1.0, 2.0, 3.0, 4.0}, d->add_priors()->mutable_upper());
  Set({9.0}, d->add_priors()->mutable_upper());

  v1::Step step;
  Set({-0.3, 0.3}, step.mutable_previous_input());  // this step's u[-1] only
  step.mutable_update()->set_shift(true);
  // N×L inputs, step-major: u[0] = (0.4, -0.4).
  ApplyStepToSpec(step, Plan({0.4, -0.4, 0.5, -0.5, 0.6, -0.6, 0.7, -0.7}), &spec);
  EXPECT_THAT(Values(d->previous_input()), ElementsAre(0.4, -0.4));
  EXPECT_THAT(Values(d->priors(0).upper()), ElementsAre(2.0, 3.0, 4.0, 4.0));
  EXPECT_THAT(Values(d->priors(1).upper()), ElementsAre(9.0));

  v1::SolveResult no_plan;  // e.g. a time limit before the first iterate: u[-1] stays
  no_plan.set_status(v1::SOLVE_STATUS_TIME_LIMIT);
  ApplyStepToSpec(v1::Step(), no_plan, &spec);
  EXPECT_THAT(Values(d->previous_input()), ElementsAre(0.4, -0.4));
}

TEST(SpecUpdateTest, ASupersededStepChangesNothing) {
  const v1::ProblemSpec original = Spec();
  v1::ProblemSpec spec = original;
  v1::Step step;
  step.add_state(3.0);
  step.add_state(4.0);
  step.mutable_update()->set_shift(true);
  v1::SolveResult superseded;
  superseded.set_status(v1::SOLVE_STATUS_SUPERSEDED);
  ApplyStepToSpec(step, superseded, &spec);
  EXPECT_EQ(spec.SerializeAsString(), original.SerializeAsString());
}

}  // namespace
}  // namespace nupmpc
