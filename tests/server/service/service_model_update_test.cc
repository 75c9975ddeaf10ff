// Step.model through the service: a linear-time-varying problem sent as model
// updates is solved as the core solves the same problem; every kind of update works
// through unary Solve and a Control stream; a rejected update names its field and leaves
// the session bit-identical; sessions that cannot take a model say so.
#include <cmath>
#include <vector>

#include "core/session/footprint.h"
#include "core/session/session.h"
#include "gmock/gmock.h"
#include "server/convert/session_cost.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;

void SetMatrix(const Eigen::MatrixXd& m, v1::Matrix* out) {
  out->set_rows(static_cast<std::uint32_t>(m.rows()));
  out->set_cols(static_cast<std::uint32_t>(m.cols()));
  out->clear_data();
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) out->add_data(m(i, j));
  }
}

Eigen::MatrixXd Perturbed(const Eigen::MatrixXd& m, int step, double size) {
  Eigen::MatrixXd out = m;
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) out(i, j) += size * std::sin(0.5 + step + 2.0 * i + 5.0 * j);
  }
  return out;
}

// masses_N30 made time-varying by hand (the reference), and the same as a Step.model.
struct Ltv {
  core::Problem problem;
  v1::ModelUpdate update;
};
Ltv TimeVarying(const core::Problem& base, double size) {
  Ltv ltv{base, {}};
  core::Problem& p = ltv.problem;
  const int N = base.horizon, M = base.num_states;
  p.A.assign(N, base.A[0]);
  p.B.assign(N, base.B[0]);
  p.state_offset.assign(N, Eigen::VectorXd::Zero(M));
  for (int n = 0; n < N; ++n) {
    p.A[n] = Perturbed(base.A[0], n, size);
    p.B[n] = Perturbed(base.B[0], n + 40, size);
    p.state_offset[n] = Eigen::VectorXd::LinSpaced(M, -size, size * std::cos(n));
    v1::ModelUpdate::MatrixAt* a = ltv.update.add_a();
    a->set_step(n);
    SetMatrix(p.A[n], a->mutable_matrix());
    v1::ModelUpdate::MatrixAt* b = ltv.update.add_b();
    b->set_step(n);
    SetMatrix(p.B[n], b->mutable_matrix());
    for (int i = 0; i < M; ++i) ltv.update.add_state_offsets(p.state_offset[n](i));
  }
  return ltv;
}

core::Solution CoreSolve(core::Problem problem, const Eigen::VectorXd& x0) {
  problem.initial_mean = x0;
  absl::StatusOr<std::unique_ptr<core::Session>> session = core::Session::Create(problem);
  EXPECT_TRUE(session.ok()) << session.status();
  core::Solution plan;
  absl::StatusOr<core::SolveSummary> summary = (*session)->Solve(&plan);
  EXPECT_TRUE(summary.ok() && summary->status == core::SolveStatus::kConverged);
  return plan;
}

double MaxInputDifference(const v1::SolveResult& result, const core::Solution& plan) {
  const int N = static_cast<int>(plan.inputs.rows()), L = static_cast<int>(plan.inputs.cols());
  EXPECT_EQ(result.inputs_size(), N * L);
  double most = 0.0;
  for (int n = 0; n < N; ++n) {
    for (int l = 0; l < L; ++l) most = std::max(most, std::abs(result.inputs(n * L + l) - plan.inputs(n, l)));
  }
  return most;
}

v1::Step StepAt(const Eigen::VectorXd& x) {
  v1::Step step;
  step.mutable_state()->Add(x.data(), x.data() + x.size());
  return step;
}

class ModelUpdateTest : public ServiceTest {
 protected:
  const bench::BenchmarkInstance masses_ = LoadInstanceOrDie("masses_N30");
  const Eigen::VectorXd x0_ = masses_.closed_loop->x1[3];
};

TEST_F(ModelUpdateTest, ATimeVaryingProblemSentAsAModelUpdateIsTheCoresSolveOfIt) {
  const Ltv ltv = TimeVarying(masses_.problem, 0.02);
  absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(SpecOrDie(masses_.problem));
  ASSERT_TRUE(created.ok()) << created.status();
  v1::Step step = StepAt(x0_);
  *step.mutable_model() = ltv.update;
  absl::StatusOr<v1::SolveResult> result = client_->Solve(created->session_id(), step);
  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_EQ(result->status(), v1::SOLVE_STATUS_CONVERGED);
  EXPECT_LE(MaxInputDifference(*result, CoreSolve(ltv.problem, x0_)), 1e-9);
}

TEST_F(ModelUpdateTest, EveryKindOfUpdateThroughAControlStreamSolvesTheUpdatedProblem) {
  auto session = client_->OpenSession(SpecOrDie(masses_.problem));
  ASSERT_TRUE(session.ok()) << session.status();
  core::Problem expected = masses_.problem;
  const int N = expected.horizon, M = expected.num_states, K = expected.num_outputs;
  const auto check = [&](const v1::Step& step, const char* what) {
    SCOPED_TRACE(what);
    absl::StatusOr<v1::SolveResult> result = (*session)->Step(step);
    ASSERT_TRUE(result.ok()) << result.status();
    ASSERT_EQ(result->status(), v1::SOLVE_STATUS_CONVERGED);
    // Warm started from the previous period: converged to the solver's tolerance.
    EXPECT_LE(MaxInputDifference(*result, CoreSolve(expected, x0_)), 1e-5);
  };
  check(StepAt(x0_), "no update");

  // Only the affine terms: a disturbance estimate for every step.
  v1::Step offsets = StepAt(x0_);
  offsets.set_warm_start(v1::WARM_START_KEEP);
  const Eigen::VectorXd disturbance = Eigen::VectorXd::LinSpaced(M, -0.05, 0.05);
  offsets.mutable_model()->mutable_state_offsets()->Add(disturbance.data(), disturbance.data() + M);
  expected.state_offset = {disturbance};
  check(offsets, "state_offsets");

  // One step of A: the time-invariant A becomes per-step.
  v1::Step one_a = StepAt(x0_);
  one_a.set_warm_start(v1::WARM_START_KEEP);
  v1::ModelUpdate::MatrixAt* a = one_a.mutable_model()->add_a();
  a->set_step(4);
  SetMatrix(Perturbed(expected.A[0], 4, 0.05), a->mutable_matrix());
  expected.A.assign(N, expected.A[0]);
  expected.A[4] = Perturbed(expected.A[0], 4, 0.05);
  check(one_a, "a[4]");

  // An output offset at one step and C at another.
  v1::Step outputs = StepAt(x0_);
  outputs.set_warm_start(v1::WARM_START_KEEP);
  v1::ModelUpdate::VectorAt* d = outputs.mutable_model()->add_output_offset();
  d->set_step(N);
  for (int k = 0; k < K; ++k) d->add_values(0.01 * k);
  v1::ModelUpdate::MatrixAt* c = outputs.mutable_model()->add_c();
  c->set_step(7);
  SetMatrix(Perturbed(expected.C[0], 7, 0.05), c->mutable_matrix());
  expected.output_offset.assign(N + 1, Eigen::VectorXd::Zero(K));
  for (int k = 0; k < K; ++k) expected.output_offset[N](k) = 0.01 * k;
  expected.C.assign(N + 1, expected.C[0]);
  expected.C[7] = Perturbed(expected.C[0], 7, 0.05);
  check(outputs, "output_offset[N], c[7]");

  // The receding horizon: everything per-step moves one step earlier, a new last A.
  v1::Step shifted = StepAt(x0_);
  shifted.mutable_model()->set_shift(true);
  v1::ModelUpdate::MatrixAt* last = shifted.mutable_model()->add_a();
  last->set_step(N - 1);
  SetMatrix(Perturbed(expected.A[0], 77, 0.05), last->mutable_matrix());
  for (int n = 0; n + 1 < N; ++n) expected.A[n] = expected.A[n + 1];
  expected.A[N - 1] = Perturbed(masses_.problem.A[0], 77, 0.05);
  for (int n = 0; n < N; ++n) {
    expected.C[n] = expected.C[n + 1];
    expected.output_offset[n] = expected.output_offset[n + 1];
  }
  check(shifted, "shift");
}

TEST_F(ModelUpdateTest, ARejectedUpdateNamesTheFieldAndLeavesTheSessionBitIdentical) {
  absl::StatusOr<v1::CreateSessionResponse> hit = client_->CreateSession(SpecOrDie(masses_.problem));
  absl::StatusOr<v1::CreateSessionResponse> twin = client_->CreateSession(SpecOrDie(masses_.problem));
  ASSERT_TRUE(hit.ok() && twin.ok());
  const Ltv ltv = TimeVarying(masses_.problem, 0.02);
  v1::Step first = StepAt(masses_.closed_loop->x1[0]);
  *first.mutable_model() = ltv.update;
  ASSERT_TRUE(client_->Solve(hit->session_id(), first).ok());
  ASSERT_TRUE(client_->Solve(twin->session_id(), first).ok());

  struct Case {
    const char* field;
    void (*spoil)(v1::ModelUpdate*);
  };
  const Case cases[] = {
      {"step.model.a[0].matrix: expected 12x12, got 12x3",
       [](v1::ModelUpdate* m) { m->mutable_a(0)->mutable_matrix()->CopyFrom(m->b(0).matrix()); }},
      {"step.model.b[29].step = 30: must be < horizon = 30",
       [](v1::ModelUpdate* m) { m->mutable_b(29)->set_step(30); }},
      // Echoed as sent (it was reported as 2147483647, clamped to an int).
      {"step.model.a[2].step = 4294967295: must be < horizon = 30",
       [](v1::ModelUpdate* m) { m->mutable_a(2)->set_step(4294967295u); }},
      {"step.model.state_offsets: expected 12 values (every step) or 360",
       [](v1::ModelUpdate* m) { m->add_state_offsets(1.0); }},
      {"step.model.a[3].matrix.data[5] = nan: must be finite",
       [](v1::ModelUpdate* m) { m->mutable_a(3)->mutable_matrix()->set_data(5, std::nan("")); }},
      {"step.model.b[1].matrix: 4294967295x0 is larger than any session's matrices",
       [](v1::ModelUpdate* m) {
         m->mutable_b(1)->mutable_matrix()->set_rows(4294967295u);
         m->mutable_b(1)->mutable_matrix()->set_cols(0);
         m->mutable_b(1)->mutable_matrix()->clear_data();
       }},
      {"step.model.c[0].matrix.data: expected 144 values",
       [](v1::ModelUpdate* m) {
         v1::ModelUpdate::MatrixAt* c = m->add_c();
         c->mutable_matrix()->set_rows(12);
         c->mutable_matrix()->set_cols(12);
       }},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.field);
    v1::Step bad = StepAt(masses_.closed_loop->x1[5]);
    *bad.mutable_model() = TimeVarying(masses_.problem, 0.03).update;
    c.spoil(bad.mutable_model());
    absl::StatusOr<v1::SolveResult> refused = client_->Solve(hit->session_id(), bad);
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(refused.status().message()), HasSubstr(c.field));
  }
  for (std::size_t t = 1; t < 4; ++t) {
    const v1::Step next = StepAt(masses_.closed_loop->x1[t]);
    absl::StatusOr<v1::SolveResult> a = client_->Solve(hit->session_id(), next);
    absl::StatusOr<v1::SolveResult> b = client_->Solve(twin->session_id(), next);
    ASSERT_TRUE(a.ok() && b.ok());
    EXPECT_EQ(a->iterations(), b->iterations());
    EXPECT_EQ(a->objective(), b->objective());
    EXPECT_TRUE(std::equal(a->inputs().begin(), a->inputs().end(), b->inputs().begin(), b->inputs().end()));
  }
}

// The storage for a per-step model is reserved before the core checks the update: a refused
// update gives it back, so the budget admits what it admitted before.
TEST_F(ModelUpdateTest, ARejectedUpdateGivesBackTheMemoryReservedForIt) {
  absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(SpecOrDie(masses_.problem));
  ASSERT_TRUE(created.ok()) << created.status();
  ASSERT_TRUE(client_->Solve(created->session_id(), StepAt(x0_)).ok());
  const std::int64_t reserved = server_->state().budget.reserved();
  v1::Step bad = StepAt(x0_);
  *bad.mutable_model() = TimeVarying(masses_.problem, 0.02).update;
  bad.mutable_model()->mutable_a(0)->mutable_matrix()->CopyFrom(bad.model().b(0).matrix());
  for (int attempt = 0; attempt < 3; ++attempt) {
    absl::StatusOr<v1::SolveResult> refused = client_->Solve(created->session_id(), bad);
    ASSERT_FALSE(refused.ok());
    EXPECT_THAT(std::string(refused.status().message()), HasSubstr("step.model.a[0].matrix: expected 12x12, got 12x3"));
    EXPECT_EQ(server_->state().budget.reserved(), reserved) << "attempt " << attempt;
  }
  // The same update, well formed, makes the model per-step: its storage is reserved and kept.
  v1::Step good = StepAt(x0_);
  *good.mutable_model() = TimeVarying(masses_.problem, 0.02).update;
  ASSERT_TRUE(client_->Solve(created->session_id(), good).ok());
  EXPECT_GT(server_->state().budget.reserved(), reserved);
}

TEST_F(ModelUpdateTest, AFleetCallCarriesEachSessionsModelAndOneBadUpdateFailsOnlyItsStep) {
  const Ltv ltv = TimeVarying(masses_.problem, 0.02);
  v1::SolveFleetRequest request;
  std::vector<std::string> ids;
  for (int s = 0; s < 3; ++s) {
    absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(SpecOrDie(masses_.problem));
    ASSERT_TRUE(created.ok()) << created.status();
    ids.push_back(created->session_id());
    v1::SolveRequest* step = request.add_steps();
    step->set_session_id(created->session_id());
    *step->mutable_step() = StepAt(x0_);
    *step->mutable_step()->mutable_model() = ltv.update;
  }
  request.mutable_steps(1)->mutable_step()->mutable_model()->mutable_a(0)->set_step(99);
  absl::StatusOr<v1::SolveFleetResponse> answered = client_->SolveFleet(request);
  ASSERT_TRUE(answered.ok()) << answered.status();
  ASSERT_EQ(answered->answers_size(), 3);
  const core::Solution reference = CoreSolve(ltv.problem, x0_);
  for (int s : {0, 2}) {
    ASSERT_EQ(answered->answers(s).error_code(), 0) << answered->answers(s).error_message();
    EXPECT_LE(MaxInputDifference(answered->answers(s).result(), reference), 1e-9);
  }
  EXPECT_EQ(answered->answers(1).error_code(), static_cast<int>(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(answered->answers(1).error_message(), HasSubstr("step.model.a[0].step = 99"));
}

TEST_F(ModelUpdateTest, APerStepModelOverThePerSessionMemoryLimitIsRefusedAndChangesNothing) {
  // A limit the time-invariant session fits in and its per-step form does not.
  const bench::BenchmarkInstance long_horizon = LoadInstanceOrDie("masses_N3000");
  const v1::ProblemSpec spec = SpecOrDie(long_horizon.problem);
  server::ServerOptions options = DefaultOptions();
  absl::StatusOr<server::SessionCost> cost = server::SpecCost(spec, options.size_limits);
  ASSERT_TRUE(cost.ok()) << cost.status();
  const core::Footprint per_step = core::EstimateFootprint({.num_states = 12,
                                                            .num_inputs = 3,
                                                            .num_outputs = 12,
                                                            .horizon = 3000,
                                                            .a_per_step = true,
                                                            .b_per_step = false,
                                                            .c_per_step = false,
                                                            .uncertain_initial_state = false,
                                                            .terminal_cost = true});
  const std::int64_t time_invariant_peak = std::max(cost->build_bytes, cost->session_bytes());
  const std::int64_t per_step_peak =
      per_step.problem_bytes + per_step.carried_bytes + per_step.workspace_bytes + per_step.transient_bytes;
  ASSERT_LT(time_invariant_peak, per_step_peak);
  options.size_limits.max_session_bytes = time_invariant_peak;
  server_->Shutdown();
  StartServer(options);

  absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(spec);
  ASSERT_TRUE(created.ok()) << created.status();
  const Eigen::VectorXd x0 = long_horizon.problem.initial_mean;
  absl::StatusOr<v1::SolveResult> before = client_->Solve(created->session_id(), StepAt(x0));
  ASSERT_TRUE(before.ok()) << before.status();
  v1::Step grow = StepAt(x0);
  grow.set_warm_start(v1::WARM_START_KEEP);
  v1::ModelUpdate::MatrixAt* a = grow.mutable_model()->add_a();
  a->set_step(10);
  SetMatrix(Perturbed(long_horizon.problem.A[0], 10, 0.01), a->mutable_matrix());
  absl::StatusOr<v1::SolveResult> refused = client_->Solve(created->session_id(), grow);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(refused.status().message()), HasSubstr("step.model: a per-step model"));
  // All-step offsets keep the storage: taken.
  v1::Step offsets = StepAt(x0);
  offsets.set_warm_start(v1::WARM_START_KEEP);
  for (int i = 0; i < 12; ++i) offsets.mutable_model()->add_state_offsets(0.0);
  absl::StatusOr<v1::SolveResult> same = client_->Solve(created->session_id(), offsets);
  ASSERT_TRUE(same.ok()) << same.status();
  EXPECT_NEAR(same->objective(), before->objective(), 1e-9 * std::abs(before->objective()));
}

TEST_F(ModelUpdateTest, SessionsThatCannotTakeAModelSaySo) {
  v1::ProblemSpec spec = SpecOrDie(masses_.problem);
  for (int l = 0; l < 3; ++l) spec.mutable_input_differences()->add_priors()->add_weight(1.0);
  absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(spec);
  ASSERT_TRUE(created.ok()) << created.status();
  v1::Step step = StepAt(x0_);
  step.mutable_model()->add_state_offsets(0.0);
  absl::StatusOr<v1::SolveResult> refused = client_->Solve(created->session_id(), step);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(refused.status().message()),
              HasSubstr("step.model: sessions with input_levels or input_differences"));
}

}  // namespace
}  // namespace nupmpc::testing
