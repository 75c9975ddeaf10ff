// MpcSession::Apply (core/session/step_update.h): a StepUpdate changes a session exactly
// as replacing its whole problem would, and a rejected one names its field and leaves the
// session bit-identical (its next plan equals that of a twin that never saw it).
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "core/session/input_mapped_session.h"
#include "core/session/session.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/util/core_session.h"
#include "tests/util/random_problem.h"

namespace nupmpc::core {
namespace {

using nupmpc::testing::MakeSession;
using nupmpc::testing::Plan;

using ::testing::HasSubstr;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Problem BoxedProblem() {
  nupmpc::testing::RandomProblemSpec spec;
  spec.M = 4;
  spec.L = 2;
  spec.K = 3;
  spec.N = 15;
  spec.seed = 7;
  return nupmpc::testing::WithBoxes(nupmpc::testing::RandomGaussianProblem(spec), 0.8, 0.0);
}

// The plan of a warm solve after the receding-horizon shift: what a control period does.
Plan SolvePeriod(MpcSession& session) {
  session.ShiftWarmStart();
  Solution solution;
  absl::StatusOr<SolveSummary> summary = session.Solve(SolveLimits{}, &solution);
  EXPECT_TRUE(summary.ok() && summary->has_plan) << summary.status();
  if (!summary.ok()) return {};
  return {solution.inputs, summary->objective, summary->iterations};
}
void ExpectSamePlan(const Plan& a, const Plan& b) {
  ASSERT_EQ(a.inputs.rows(), b.inputs.rows());
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.objective, b.objective);
  EXPECT_TRUE(a.inputs == b.inputs) << "max difference " << (a.inputs - b.inputs).cwiseAbs().maxCoeff();
}

ComponentPriors GaussianTargets(int index, int steps, double first, double slope) {
  ComponentPriors c{.index = index, .priors = {}};
  for (int n = 0; n < steps; ++n) c.priors.push_back(ScalarPrior::Gaussian(first + slope * n, 0.5));
  return c;
}

TEST(StepUpdate, ChangesTheSessionAsReplacingTheWholeProblemDoes) {
  const Problem base = BoxedProblem();
  const int N = base.horizon, L = base.num_inputs, K = base.num_outputs;
  std::unique_ptr<Session> applied = MakeSession(base), replaced = MakeSession(base);
  ASSERT_TRUE(applied && replaced);
  ExpectSamePlan(SolvePeriod(*applied), SolvePeriod(*replaced));

  StepUpdate update;
  update.state = Eigen::VectorXd::Constant(base.num_states, 0.3);
  update.shift = true;
  update.outputs.push_back(GaussianTargets(1, N + 1, 0.2, 0.01));
  update.inputs.push_back({.index = 0, .priors = std::vector<ScalarPrior>(N, ScalarPrior::Box(-0.5, 0.5, 2.0))});
  ASSERT_TRUE(applied->Apply(update).ok());

  // The same change written out on a copy of the problem.
  Problem expected = base;
  expected.initial_mean = *update.state;
  for (int n = 0; n + 1 < N; ++n) {
    for (int l = 0; l < L; ++l) expected.mutable_input_prior(n, l) = base.input_prior(n + 1, l);
  }
  for (int n = 0; n < N; ++n) {
    for (int k = 0; k < K; ++k) expected.mutable_output_prior(n, k) = base.output_prior(n + 1, k);
  }
  for (int n = 0; n <= N; ++n) expected.mutable_output_prior(n, 1) = update.outputs[0].priors[n];
  for (int n = 0; n < N; ++n) expected.mutable_input_prior(n, 0) = update.inputs[0].priors[n];
  ASSERT_TRUE(replaced->Update(expected).ok());
  ExpectSamePlan(SolvePeriod(*applied), SolvePeriod(*replaced));
}

struct Refusal {
  const char* what;
  StepUpdate update;
  absl::StatusCode code;
  const char* field;
};

std::vector<Refusal> RefusalsFor(const Problem& p) {
  const int M = p.num_states, N = p.horizon;
  std::vector<Refusal> out;
  const auto add = [&](const char* what, absl::StatusCode code, const char* field, auto fill) {
    Refusal r{what, {}, code, field};
    fill(r.update);
    out.push_back(std::move(r));
  };
  add("state of the wrong size", absl::StatusCode::kFailedPrecondition, "state: expected",
      [&](StepUpdate& u) { u.state = Eigen::VectorXd::Zero(M + 1); });
  add("non-finite state", absl::StatusCode::kInvalidArgument, "state[1]", [&](StepUpdate& u) {
    u.state = Eigen::VectorXd::Zero(M);
    (*u.state)(1) = kNaN;
  });
  add("input index out of range", absl::StatusCode::kInvalidArgument, "update.inputs[0].index",
      [&](StepUpdate& u) { u.inputs.push_back({.index = p.num_inputs, .priors = std::vector<ScalarPrior>(N)}); });
  add("output priors for too few steps", absl::StatusCode::kInvalidArgument, "update.outputs[0].prior",
      [&](StepUpdate& u) { u.outputs.push_back(GaussianTargets(0, N, 0.0, 0.0)); });
  add("a non-finite target after a valid entry", absl::StatusCode::kInvalidArgument, "update.outputs[1].prior",
      [&](StepUpdate& u) {
        u.shift = true;
        u.outputs.push_back(GaussianTargets(0, N + 1, 1.0, 0.0));
        u.outputs.push_back(GaussianTargets(2, N + 1, kNaN, 0.0));
      });
  add("rounding marks on an output", absl::StatusCode::kInvalidArgument, "rounds_with_next", [&](StepUpdate& u) {
    u.outputs.push_back(GaussianTargets(0, N + 1, 1.0, 0.0));
    u.outputs.back().priors[3].rounds_with_next = true;
  });
  add("previous_input on a session without input differences", absl::StatusCode::kInvalidArgument, "previous_input",
      [&](StepUpdate& u) { u.previous_input = Eigen::VectorXd::Zero(p.num_inputs); });
  add("reference on a linear session", absl::StatusCode::kInvalidArgument, "reference",
      [&](StepUpdate& u) { u.reference = Eigen::VectorXd::Zero(1); });
  return out;
}

TEST(StepUpdate, ARefusedUpdateNamesItsFieldAndLeavesTheSessionBitIdentical) {
  const Problem base = BoxedProblem();
  std::unique_ptr<Session> refused = MakeSession(base), twin = MakeSession(base);
  ASSERT_TRUE(refused && twin);
  ExpectSamePlan(SolvePeriod(*refused), SolvePeriod(*twin));
  for (const Refusal& r : RefusalsFor(base)) {
    const absl::Status status = refused->Apply(r.update);
    EXPECT_EQ(status.code(), r.code) << r.what << ": " << status;
    EXPECT_THAT(std::string(status.message()), HasSubstr(r.field)) << r.what;
  }
  StepUpdate next;
  next.state = Eigen::VectorXd::Constant(base.num_states, -0.2);
  ASSERT_TRUE(refused->Apply(next).ok());
  ASSERT_TRUE(twin->Apply(next).ok());
  ExpectSamePlan(SolvePeriod(*refused), SolvePeriod(*twin));
}

TEST(StepUpdate, PriorsAnotherAlgorithmWouldNeedAreRefusedWhenTheAlgorithmIsForced) {
  const Problem base = BoxedProblem();  // input boxes only: IBFFD
  SolverOptions forced;
  forced.algorithm = Algorithm::kIbffd;
  absl::StatusOr<std::unique_ptr<Session>> refused = Session::Create(base, forced),
                                           twin = Session::Create(base, forced);
  ASSERT_TRUE(refused.ok() && twin.ok());
  StepUpdate bounded;  // an output box: IBFFD cannot take it
  bounded.outputs.push_back(
      {.index = 0, .priors = std::vector<ScalarPrior>(base.horizon + 1, ScalarPrior::Box(-1, 1))});
  EXPECT_FALSE((*refused)->Apply(bounded).ok());
  ExpectSamePlan(SolvePeriod(**refused), SolvePeriod(**twin));
}

// A plant with one input whose differences are rate-limited, wrapped by InputMappedSession.
std::unique_ptr<MpcSession> RateLimitedSession(const Problem& base) {
  InputMap map;
  map.differences = true;
  map.difference_priors.assign(static_cast<std::size_t>(base.horizon) * base.num_inputs, ScalarPrior::Box(-0.1, 0.1));
  map.previous_input = Eigen::VectorXd::Constant(base.num_inputs, 0.05);
  absl::StatusOr<Problem> mapped = MapInputs(base, map);
  EXPECT_TRUE(mapped.ok()) << mapped.status();
  absl::StatusOr<std::unique_ptr<Session>> inner = Session::Create(*std::move(mapped));
  EXPECT_TRUE(inner.ok()) << inner.status();
  return InputMappedSession::Wrap(*std::move(inner), std::move(map), DimensionsOf(base));
}

TEST(StepUpdate, AnInputMappedSessionRefusesWhatItsCallerCannotChange) {
  nupmpc::testing::RandomProblemSpec spec;
  spec.seed = 3;
  const Problem base = nupmpc::testing::RandomGaussianProblem(spec);
  std::unique_ptr<MpcSession> refused = RateLimitedSession(base), twin = RateLimitedSession(base);
  ASSERT_TRUE(refused && twin);
  EXPECT_EQ(refused->dimensions().num_outputs, base.num_outputs);
  EXPECT_EQ(refused->problem().num_outputs, base.num_outputs + base.num_inputs);
  const int N = base.horizon;
  std::vector<Refusal> refusals;
  refusals.push_back({"input priors", {}, absl::StatusCode::kFailedPrecondition, "update.inputs"});
  refusals.back().update.inputs.push_back({.index = 0, .priors = std::vector<ScalarPrior>(N)});
  refusals.push_back(
      {"an output the caller does not have", {}, absl::StatusCode::kInvalidArgument, "update.outputs[0].index"});
  refusals.back().update.outputs.push_back(GaussianTargets(base.num_outputs, N + 1, 0.0, 0.0));
  refusals.push_back({"previous_input of the wrong size", {}, absl::StatusCode::kFailedPrecondition, "previous_input"});
  refusals.back().update.previous_input = Eigen::VectorXd::Zero(base.num_inputs + 1);
  refusals.push_back({"non-finite previous_input", {}, absl::StatusCode::kInvalidArgument, "previous_input[0]"});
  refusals.back().update.previous_input = Eigen::VectorXd::Constant(base.num_inputs, kNaN);
  for (const Refusal& r : refusals) {
    const absl::Status status = refused->Apply(r.update);
    EXPECT_EQ(status.code(), r.code) << r.what << ": " << status;
    EXPECT_THAT(std::string(status.message()), HasSubstr(r.field)) << r.what;
  }
  StepUpdate next;
  next.state = Eigen::VectorXd::Constant(base.num_states, 0.1);
  next.previous_input = Eigen::VectorXd::Constant(base.num_inputs, -0.02);
  ASSERT_TRUE(refused->Apply(next).ok());
  ASSERT_TRUE(twin->Apply(next).ok());
  ExpectSamePlan(SolvePeriod(*refused), SolvePeriod(*twin));
}

TEST(StepUpdate, AShiftOnInputDifferencesKeepsTheAppliedInputFree) {
  // The inner outputs K..K+L-1 carry u[n-1] at step n; the fixed u[-1] at step 0 must keep
  // its free prior when the priors on u move one step earlier.
  nupmpc::testing::RandomProblemSpec spec;
  spec.seed = 5;
  const Problem base = nupmpc::testing::RandomGaussianProblem(spec);
  std::unique_ptr<MpcSession> session = RateLimitedSession(base);
  ASSERT_TRUE(session);
  const int K = base.num_outputs, N = base.horizon;
  const Problem before = session->problem();
  ASSERT_TRUE(before.output_prior(1, K).has_gaussian());   // the prior on u[0]
  ASSERT_FALSE(before.output_prior(0, K).has_gaussian());  // u[-1]: given, no prior
  StepUpdate shift;
  shift.shift = true;
  ASSERT_TRUE(session->Apply(shift).ok());
  const Problem& after = session->problem();
  for (int l = 0; l < base.num_inputs; ++l) {
    EXPECT_FALSE(after.output_prior(0, K + l).has_gaussian()) << "input " << l;
    EXPECT_EQ(after.output_prior(0, K + l).kind, PriorKind::kNone) << "input " << l;
    for (int n = 1; n <= N; ++n) {
      const int from = std::min(n + 1, N);
      EXPECT_EQ(after.output_prior(n, K + l).mean, before.output_prior(from, K + l).mean) << "step " << n;
      EXPECT_EQ(after.output_prior(n, K + l).variance, before.output_prior(from, K + l).variance) << "step " << n;
    }
  }
}

}  // namespace
}  // namespace nupmpc::core
