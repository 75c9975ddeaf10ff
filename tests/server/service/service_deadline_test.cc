// Steps with deadlines (ProblemSpec.timing, Step.budget_ms) through the service: a step
// whose deadline passed while it waited behind other work is answered at once without a
// plan (or solved late when the session asks), and a step whose solve cannot converge
// within its budget is answered by it with the best plan reached for its own state, and
// one left less time than a pass is answered at once. The
// machine's speed only sets the budgets (from a measured pass), never what is asserted.
#include <chrono>
#include <future>

#include "gmock/gmock.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

using std::chrono::milliseconds;

class ServiceDeadlineTest : public ServiceTest {
 protected:
  void SetUp() override {
    spdlog::set_level(spdlog::level::warn);
    server::ServerOptions options = DefaultOptions();
    options.worker_threads = 1;
    options.inline_solve_max_ms = 0.0;  // every step through the pool's queue
    StartServer(options);
  }

  // A unary session of `name`, its spec changed by `edit`.
  std::string CreateSession(const std::string& name, void (*edit)(v1::ProblemSpec*) = nullptr) {
    v1::ProblemSpec spec = SpecOrDie(LoadInstanceOrDie(name).problem);
    if (edit != nullptr) edit(&spec);
    absl::StatusOr<v1::CreateSessionResponse> created = client_->CreateSession(spec);
    EXPECT_TRUE(created.ok()) << created.status();
    return created.ok() ? created->session_id() : std::string();
  }

  static v1::Step StepAt(const Eigen::VectorXd& x, double budget_ms = 0.0) {
    v1::Step step;
    step.mutable_state()->Add(x.data(), x.data() + x.size());
    step.set_budget_ms(budget_ms);
    return step;
  }
};

TEST_F(ServiceDeadlineTest, AStepQueuedPastItsDeadlineIsAnsweredAtOnceWithoutAPlanOrSolvedLateIfAsked) {
  const bench::BenchmarkInstance masses = LoadInstanceOrDie("masses_N30");
  const Eigen::VectorXd x = masses.closed_loop->x1.at(3);
  const std::string dropping = CreateSession("masses_N30");
  const std::string solving_late =
      CreateSession("masses_N30", [](v1::ProblemSpec* s) { s->mutable_timing()->set_solve_late_steps(true); });
  // The long instance's cold solve holds the only worker for many milliseconds.
  const std::string long_session = CreateSession("random_outbox_M40_K20_L20_N1000_s1");
  const bench::BenchmarkInstance long_instance = LoadInstanceOrDie("random_outbox_M40_K20_L20_N1000_s1");
  auto busy = std::async(std::launch::async,
                         [&] { return client_->Solve(long_session, StepAt(long_instance.problem.initial_mean)); });
  // Queued behind it with a 1 ms budget: past its deadline by the time the worker is free.
  std::this_thread::sleep_for(milliseconds(20));  // the long solve has started (it is alone)
  auto dropped = std::async(std::launch::async, [&] { return client_->Solve(dropping, StepAt(x, 1.0)); });
  auto late = std::async(std::launch::async, [&] { return client_->Solve(solving_late, StepAt(x, 1.0)); });
  ASSERT_TRUE(busy.get().ok());

  absl::StatusOr<v1::SolveResult> answer = dropped.get();
  ASSERT_TRUE(answer.ok()) << answer.status();
  EXPECT_EQ(answer->deadline(), v1::DEADLINE_OUTCOME_QUEUED_PAST_DEADLINE);
  EXPECT_EQ(answer->status(), v1::SOLVE_STATUS_TIME_LIMIT);
  EXPECT_FALSE(answer->has_plan());
  EXPECT_EQ(answer->inputs_size(), 0);
  EXPECT_EQ(answer->iterations(), 0u) << "it was solved although its deadline had passed";
  EXPECT_LT(answer->deadline_slack_ms(), 0.0);

  absl::StatusOr<v1::SolveResult> solved_late = late.get();
  ASSERT_TRUE(solved_late.ok()) << solved_late.status();
  EXPECT_EQ(solved_late->deadline(), v1::DEADLINE_OUTCOME_QUEUED_PAST_DEADLINE);
  EXPECT_TRUE(solved_late->has_plan());
  EXPECT_EQ(solved_late->status(), v1::SOLVE_STATUS_CONVERGED);
  ASSERT_GE(solved_late->states_size(), x.size());
  for (int i = 0; i < x.size(); ++i) EXPECT_EQ(solved_late->states(i), x(i));  // the plan is for its own state

  const server::ServerState& state = server_->state();
  EXPECT_EQ(state.metrics.deadlines(v1::DEADLINE_OUTCOME_QUEUED_PAST_DEADLINE), 2u);
}

TEST_F(ServiceDeadlineTest, AStepThatCannotConvergeInItsBudgetIsAnsweredByItWithTheBestPlanReached) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("random_outbox_M40_K20_L20_N1000_s1");
  const Eigen::VectorXd x = inst.problem.initial_mean;
  const std::string session = CreateSession("random_outbox_M40_K20_L20_N1000_s1");
  // A first solve without a deadline: how long one pass takes here, and how many a cold
  // solve needs.
  absl::StatusOr<v1::SolveResult> full = client_->Solve(session, StepAt(x));
  ASSERT_TRUE(full.ok()) << full.status();
  ASSERT_GE(full->iterations(), 8u) << "the instance converges too fast to test an anytime answer";
  const double pass_ms = full->solve_ms() / full->iterations();
  // The same step cold, with time for about half its passes.
  v1::Step step = StepAt(x, pass_ms * full->iterations() / 2);
  step.set_warm_start(v1::WARM_START_COLD);
  absl::StatusOr<v1::SolveResult> anytime = client_->Solve(session, step);
  ASSERT_TRUE(anytime.ok()) << anytime.status();
  EXPECT_EQ(anytime->status(), v1::SOLVE_STATUS_TIME_LIMIT);
  EXPECT_TRUE(anytime->has_plan());  // the last finite iterate of this solve, for this step's state
  EXPECT_GE(anytime->iterations(), 1u);
  EXPECT_LT(anytime->iterations(), full->iterations());
  EXPECT_EQ(anytime->deadline(), v1::DEADLINE_OUTCOME_MET) << "slack " << anytime->deadline_slack_ms() << " ms";
  EXPECT_GE(anytime->deadline_slack_ms(), 0.0);
  EXPECT_EQ(anytime->inputs_size(), full->inputs_size());
  EXPECT_NE(anytime->objective(), full->objective());  // an earlier iterate, not the converged plan
}

TEST_F(ServiceDeadlineTest, AStepLeftLessTimeThanOnePassIsAnsweredAtOnceWithoutSpendingIt) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("random_outbox_M40_K20_L20_N1000_s1");
  const Eigen::VectorXd x = inst.problem.initial_mean;
  const std::string session = CreateSession("random_outbox_M40_K20_L20_N1000_s1");
  absl::StatusOr<v1::SolveResult> full = client_->Solve(session, StepAt(x));  // sets the session's pass time
  ASSERT_TRUE(full.ok()) << full.status();
  ASSERT_GE(full->iterations(), 2u);
  const double pass_ms = full->solve_ms() / full->iterations();
  // Half a pass: no plan could be ready by the deadline, so none is started.
  v1::Step step = StepAt(x, pass_ms / 2);
  step.set_warm_start(v1::WARM_START_COLD);
  absl::StatusOr<v1::SolveResult> answer = client_->Solve(session, step);
  ASSERT_TRUE(answer.ok()) << answer.status();
  EXPECT_EQ(answer->deadline(), v1::DEADLINE_OUTCOME_SOLVE_TOO_LONG);
  EXPECT_EQ(answer->status(), v1::SOLVE_STATUS_TIME_LIMIT);
  EXPECT_FALSE(answer->has_plan());
  EXPECT_EQ(answer->iterations(), 0u) << "a pass was spent that could not end by the deadline";
  EXPECT_EQ(server_->state().metrics.deadlines(v1::DEADLINE_OUTCOME_SOLVE_TOO_LONG), 1u);

  // A session that prefers a late plan to none still gets one.
  const std::string solving_late = CreateSession("random_outbox_M40_K20_L20_N1000_s1", [](v1::ProblemSpec* s) {
    s->mutable_timing()->set_solve_late_steps(true);
  });
  ASSERT_TRUE(client_->Solve(solving_late, StepAt(x)).ok());
  absl::StatusOr<v1::SolveResult> late = client_->Solve(solving_late, step);
  ASSERT_TRUE(late.ok()) << late.status();
  EXPECT_GE(late->iterations(), 1u);
  EXPECT_TRUE(late->has_plan());
}

TEST_F(ServiceDeadlineTest, StepsWithoutADeadlineSayNothingOfOne) {
  const bench::BenchmarkInstance masses = LoadInstanceOrDie("masses_N30");
  const std::string session = CreateSession("masses_N30");
  absl::StatusOr<v1::SolveResult> result = client_->Solve(session, StepAt(masses.closed_loop->x1.at(0)));
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->deadline(), v1::DEADLINE_OUTCOME_UNSPECIFIED);
  EXPECT_EQ(result->deadline_slack_ms(), 0.0);
}

TEST_F(ServiceDeadlineTest, ASessionPeriodIsEveryStepsBudgetAndBadTimingIsRefusedNamingTheField) {
  const bench::BenchmarkInstance masses = LoadInstanceOrDie("masses_N30");
  const std::string session =
      CreateSession("masses_N30", [](v1::ProblemSpec* s) { s->mutable_timing()->set_period_ms(1000.0); });
  absl::StatusOr<v1::SolveResult> result = client_->Solve(session, StepAt(masses.closed_loop->x1.at(0)));
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->deadline(), v1::DEADLINE_OUTCOME_MET);
  EXPECT_GT(result->deadline_slack_ms(), 0.0);
  EXPECT_LE(result->deadline_slack_ms(), 1000.0);

  v1::ProblemSpec bad = SpecOrDie(masses.problem);
  bad.mutable_timing()->set_period_ms(-1.0);
  absl::StatusOr<v1::CreateSessionResponse> refused = client_->CreateSession(bad);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(refused.status().message()), ::testing::HasSubstr("spec.timing.period_ms"));
  v1::Step negative = StepAt(masses.closed_loop->x1.at(0), -5.0);
  absl::StatusOr<v1::SolveResult> refused_step = client_->Solve(session, negative);
  EXPECT_EQ(refused_step.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(refused_step.status().message()), ::testing::HasSubstr("step.budget_ms"));
}

}  // namespace
}  // namespace nupmpc::testing
