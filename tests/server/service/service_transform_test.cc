// Multi-level inputs and input-difference priors through the v1 API: the server's plan
// is the core helpers' plan, reported in the client's own inputs, outputs and states;
// sessions carry u[-1] from one step to the next; misuse is refused naming the field.
#include "core/examples/scenarios/dac.h"
#include "core/model/input_differences.h"
#include "core/model/multilevel_inputs.h"
#include "core/session/session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;
constexpr int kN = 15;
constexpr double kRate = 0.05;

core::Problem SmallPlant() {
  core::Problem p = core::Problem::TimeInvariant(2, 1, 1, kN);
  p.A[0] << 1.0, 0.1, 0.0, 0.98;
  p.B[0] << 0.005, 0.1;
  p.C[0] << 1.0, 0.0;
  p.initial_mean << -0.4, 0.0;
  p.input_priors.assign(kN, core::ScalarPrior::Box(-0.5, 0.5).WithGaussian(0.0, 10.0));
  p.output_priors.assign(kN + 1, core::ScalarPrior::Gaussian(1.0, 1.0 / 50.0));
  return p;
}

v1::ProblemSpec WithRateLimit(v1::ProblemSpec spec, double previous) {
  v1::InputDifferences* d = spec.mutable_input_differences();
  v1::ComponentPrior* c = d->add_priors();
  c->set_kind(v1::PRIOR_KIND_BOX);
  c->add_lower(-kRate);
  c->add_upper(kRate);
  c->add_weight(1.0);
  d->add_previous_input(previous);
  return spec;
}

TEST_F(ServiceTest, InputDifferencesGiveTheCoreHelpersPlanInTheClientsTerms) {
  const core::Problem p = SmallPlant();
  const v1::ProblemSpec spec = WithRateLimit(SpecOrDie(p), 0.1);
  absl::StatusOr<v1::SolveResult> once = client_->SolveOnce(spec);
  ASSERT_TRUE(once.ok()) << once.status();
  ASSERT_EQ(once->inputs_size(), kN);            // u, not Δu plus carried states
  ASSERT_EQ(once->outputs_size(), kN + 1);       // the spec's one output
  ASSERT_EQ(once->states_size(), (kN + 1) * 2);  // the spec's two states

  auto augmented = core::AugmentWithInputDifferences(
      p, std::vector<core::ScalarPrior>(kN, core::ScalarPrior::Box(-kRate, kRate).WithGaussian(0.0, 1.0)),
      Eigen::VectorXd::Constant(1, 0.1));
  ASSERT_TRUE(augmented.ok());
  auto session = core::Session::Create(*augmented);
  core::Solution plan;
  ASSERT_TRUE((*session)->Solve(&plan).ok());
  const Eigen::MatrixXd u = core::InputsFromDifferences(plan.inputs, Eigen::VectorXd::Constant(1, 0.1));
  double previous = 0.1;
  for (int n = 0; n < kN; ++n) {
    EXPECT_EQ(once->inputs(n), u(n, 0)) << "step " << n;
    EXPECT_LE(std::abs(once->inputs(n) - previous), kRate + 1e-9) << "step " << n;
    previous = once->inputs(n);
  }
}

TEST_F(ServiceTest, AnInputDifferenceSessionCarriesTheAppliedInput) {
  const v1::ProblemSpec spec = WithRateLimit(SpecOrDie(SmallPlant()), 0.0);
  absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(spec);
  ASSERT_TRUE(created.ok()) << created.status();
  EXPECT_EQ(created->dimensions().num_states(), 2u);  // the client's, not the augmented 3
  v1::Step step;
  step.add_state(-0.4);
  step.add_state(0.0);
  absl::StatusOr<v1::SolveResult> first = client_->Solve(created->session_id(), step);
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_LE(std::abs(first->inputs(0)), kRate + 1e-9);
  // Next period: u[-1] is the applied first input, so the new first input moves at most kRate from it.
  step.set_state(0, -0.39);
  absl::StatusOr<v1::SolveResult> second = client_->Solve(created->session_id(), step);
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_LE(std::abs(second->inputs(0) - first->inputs(0)), kRate + 1e-9);
  EXPECT_GT(second->inputs(0), kRate + 1e-6);  // it did move on from the carried input
  // An explicit previous_input overrides the carried one.
  step.add_previous_input(-0.3);
  absl::StatusOr<v1::SolveResult> third = client_->Solve(created->session_id(), step);
  ASSERT_TRUE(third.ok()) << third.status();
  EXPECT_LE(std::abs(third->inputs(0) + 0.3), kRate + 1e-9);
}

TEST_F(ServiceTest, MultiLevelInputsGiveTheCoreHelpersPlanOnTheLevels) {
  core::Problem p = examples::DacPlant(8);
  p.output_priors.assign(9, core::ScalarPrior::Gaussian(0.6, 0.01));
  v1::ProblemSpec spec = SpecOrDie(p);
  v1::InputLevels* levels = spec.add_input_levels();
  levels->set_input(0);
  levels->set_count(3);
  levels->set_lowest(0.0);
  levels->set_spacing(0.5);
  spec.mutable_options()->set_max_iterations(300);
  absl::StatusOr<v1::SolveResult> once = client_->SolveOnce(spec);
  ASSERT_TRUE(once.ok()) << once.status();
  EXPECT_TRUE(once->rounded());
  ASSERT_EQ(once->inputs_size(), 8);

  const std::vector<core::InputLevels> core_levels = {{.count = 3, .lowest = 0.0, .spacing = 0.5}};
  auto expanded = core::ExpandMultiLevelInputs(p, core_levels);
  ASSERT_TRUE(expanded.ok());
  core::SolverOptions options;
  options.max_iterations = 300;
  auto session = core::Session::Create(*expanded, options);
  core::Solution plan;
  ASSERT_TRUE((*session)->Solve(&plan).ok());
  const Eigen::MatrixXd u = core::InputsFromLevels(plan.inputs, core_levels);
  for (int n = 0; n < 8; ++n) {
    EXPECT_EQ(once->inputs(n), u(n, 0));
    EXPECT_TRUE(once->inputs(n) == 0.0 || once->inputs(n) == 0.5 || once->inputs(n) == 1.0);
  }
}

TEST_F(ServiceTest, TransformMisuseIsRefusedNamingTheField) {
  const v1::ProblemSpec plain = SpecOrDie(SmallPlant());
  v1::ProblemSpec own_prior = plain;  // input 0 has a box and a weight
  own_prior.add_input_levels()->set_input(0);
  own_prior.mutable_input_levels(0)->set_count(3);
  own_prior.mutable_input_levels(0)->set_spacing(1.0);
  EXPECT_THAT(std::string(client_->SolveOnce(own_prior).status().message()), HasSubstr("spec.input_priors[0]"));
  v1::ProblemSpec both = WithRateLimit(own_prior, 0.0);
  EXPECT_THAT(std::string(client_->SolveOnce(both).status().message()), HasSubstr("spec.input_differences"));
  v1::ProblemSpec wrong_count = WithRateLimit(plain, 0.0);
  wrong_count.mutable_input_differences()->add_priors();
  EXPECT_THAT(std::string(client_->SolveOnce(wrong_count).status().message()),
              HasSubstr("spec.input_differences.priors"));
  v1::ProblemSpec bad_level = plain;
  bad_level.mutable_input_priors(0)->Clear();
  bad_level.add_input_levels()->set_input(0);  // count 0
  EXPECT_THAT(std::string(client_->SolveOnce(bad_level).status().message()), HasSubstr("spec.input_levels[0].count"));

  absl::StatusOr<v1::CreateSessionResponse> normal = client_->CreateSession(plain);
  ASSERT_TRUE(normal.ok());
  v1::Step step;
  step.add_previous_input(0.0);
  EXPECT_THAT(client_->Solve(normal->session_id(), step).status(),
              ::testing::Property(&absl::Status::message, HasSubstr("step.previous_input")));
  absl::StatusOr<v1::CreateSessionResponse> limited = client_->CreateSession(WithRateLimit(plain, 0.0));
  ASSERT_TRUE(limited.ok());
  v1::Step update;
  update.mutable_update()->add_inputs()->set_index(0);
  const absl::Status refused = client_->Solve(limited->session_id(), update).status();
  EXPECT_EQ(refused.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(refused.message()), HasSubstr("step.update.inputs"));
}

}  // namespace
}  // namespace nupmpc::testing
