// Time limits and cancellation inside a pass (core/algorithms/interrupt.h): a
// long pass must not hold its worker past a deadline.
// Bounds are relative to one pass of the same problem measured in the same test (the
// machine is shared and may run under a sanitizer): never an absolute speed.
#include "core/algorithms/interrupt.h"

#include <atomic>
#include <chrono>
#include <climits>
#include <cmath>
#include <thread>

#include "core/session/footprint.h"
#include "core/session/session.h"
#include "gtest/gtest.h"
#include "loadtest/instances/benchmark_instance.h"
#include "tests/util/benchmark_files.h"
#include "tests/util/random_problem.h"

namespace nupmpc::core {
namespace {

using Clock = std::chrono::steady_clock;
using ::nupmpc::testing::LoadInstanceOrDie;
const std::string kDir = NUPMPC_BENCHMARK_DIR;

double Since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double ReferenceJ(const std::string& name) {
  auto refs = bench::LoadReferences(kDir + "/reference.json");
  EXPECT_TRUE(refs.ok()) << refs.status();
  return refs->at(name).J_star;
}

// The fastest of three cold one-pass solves.
double OnePassSeconds(Session& session) {
  double best = 1e300;
  for (int i = 0; i < 3; ++i) {
    SolveLimits one;
    one.max_iterations = 1;
    one.warm_start = false;
    const auto t = Clock::now();
    EXPECT_TRUE(session.Solve(one, nullptr).ok());
    best = std::min(best, Since(t));
  }
  return best;
}

// A problem whose pass takes long enough to be interrupted reliably inside it (IFFBDD on
// an augmented state of 165: ~10⁸ flops per step, ~10¹⁰ per pass).
Problem LargeProblem() {
  testing::RandomProblemSpec spec;
  spec.M = 150;
  spec.L = 15;
  spec.K = 150;
  spec.N = 80;
  spec.time_varying = false;
  return testing::WithBoxes(testing::RandomGaussianProblem(spec), 0.5, 50.0);
}

SolverOptions NeverConverging() {
  SolverOptions options;
  options.polish_after_stable_iterations = 0;
  options.objective_tolerance = 1e-300;
  options.violation_tolerance = 1e-300;
  return options;
}

void ExpectNoPlan(const SolveSummary& s, const Solution& solution) {
  EXPECT_FALSE(s.has_plan) << s.Describe();
  EXPECT_EQ(s.iterations, 0) << s.Describe();
  EXPECT_TRUE(std::isnan(s.objective));
  EXPECT_TRUE(std::isnan(s.max_violation));
  EXPECT_EQ(solution.inputs.size(), 0);
  EXPECT_EQ(solution.states.size(), 0);
  EXPECT_EQ(solution.outputs.size(), 0);
}

// On a small problem the passes never read the clock: the interval (from the flops per
// step) exceeds the horizon, so a limit costs one clock read per pass, in the driver.
TEST(Interrupt, SmallProblemsPollOncePerPassAtMost) {
  testing::RandomProblemSpec spec;
  spec.M = 2;
  spec.L = 1;
  spec.K = 1;
  spec.N = 20;
  const Problem p = testing::RandomGaussianProblem(spec);
  std::atomic<bool> cancel{false};
  SolveLimits limits;
  limits.time_limit_seconds = 10.0;
  limits.cancel = &cancel;
  for (const Algorithm a : {Algorithm::kIake, Algorithm::kIbffd, Algorithm::kIffbdd}) {
    const Interrupt interrupt(limits, Clock::now(), EstimateFootprint(ShapeOf(p, a)).flops_per_step);
    EXPECT_GT(interrupt.pass_interval(), 4 * spec.N) << AlgorithmName(a);
  }
  // Large ones poll every step.
  const Problem large = LargeProblem();
  const Interrupt interrupt(limits, Clock::now(), EstimateFootprint(ShapeOf(large)).flops_per_step);
  EXPECT_EQ(interrupt.pass_interval(), 1);
  // No limits: never armed.
  EXPECT_EQ(Interrupt(SolveLimits{}, Clock::now(), 1e12).pass_interval(), INT_MAX);
}

TEST(Interrupt, StopPollReadsEveryIntervalAndStaysFired) {
  std::atomic<bool> cancel{false};
  SolveLimits limits;
  limits.cancel = &cancel;
  Interrupt interrupt(limits, Clock::now(), 0.0);
  StopPoll poll(&interrupt, 3);
  EXPECT_FALSE(poll());
  cancel = true;
  EXPECT_FALSE(poll());  // not read yet
  EXPECT_TRUE(poll());   // third call reads the flag
  cancel = false;
  EXPECT_TRUE(poll());  // sticky
  EXPECT_EQ(*interrupt.reason(), SolveStatus::kCancelled);
  StopPoll later(&interrupt, 1000);
  EXPECT_TRUE(later()) << "a new loop sees a fired interrupt at once";
  StopPoll none(nullptr);
  EXPECT_FALSE(none());
}

class LargeSolve : public ::testing::Test {
 protected:
  void SetUp() override {
    problem_ = LargeProblem();
    auto session = Session::Create(problem_, NeverConverging());
    ASSERT_TRUE(session.ok()) << session.status();
    session_ = *std::move(session);
    pass_ = OnePassSeconds(*session_);
    std::printf("one pass: %.3f s\n", pass_);
  }
  Problem problem_;
  std::unique_ptr<Session> session_;
  double pass_ = 0.0;
};

TEST_F(LargeSolve, ATimeLimitInsideTheFirstPassReturnsWithoutAPlan) {
  SolveLimits limits;
  limits.time_limit_seconds = 0.2 * pass_;
  limits.warm_start = false;
  Solution solution;
  const auto t = Clock::now();
  auto s = session_->Solve(limits, &solution);
  const double took = Since(t);
  ASSERT_TRUE(s.ok());
  std::printf("limit %.3f s, returned after %.3f s (%.0f %% of a pass past the limit)\n", limits.time_limit_seconds,
              took, 100.0 * (took - limits.time_limit_seconds) / pass_);
  EXPECT_EQ(s->status, SolveStatus::kTimeLimit) << s->Describe();
  ExpectNoPlan(*s, solution);
  // Well before the pass would have ended (it would take pass_ from the start).
  EXPECT_LT(took, 0.6 * pass_);
}

TEST_F(LargeSolve, ACancelInsideTheFirstPassReturnsWithoutAPlan) {
  std::atomic<bool> cancel{false};
  SolveLimits limits;
  limits.cancel = &cancel;
  limits.warm_start = false;
  Solution solution;
  const auto t = Clock::now();
  std::thread canceller([&] {
    std::this_thread::sleep_for(std::chrono::duration<double>(0.2 * pass_));
    cancel = true;
  });
  auto s = session_->Solve(limits, &solution);
  const double took = Since(t);
  canceller.join();
  ASSERT_TRUE(s.ok());
  std::printf("cancelled at %.3f s, returned after %.3f s\n", 0.2 * pass_, took);
  EXPECT_EQ(s->status, SolveStatus::kCancelled) << s->Describe();
  ExpectNoPlan(*s, solution);
  EXPECT_LT(took, 0.6 * pass_);
}

TEST_F(LargeSolve, ACancelAfterSomePassesStillReturnsNoPlan) {
  std::atomic<bool> cancel{false};
  SolveLimits limits;
  limits.cancel = &cancel;
  limits.warm_start = false;
  Solution solution;
  std::thread canceller([&] {
    std::this_thread::sleep_for(std::chrono::duration<double>(1.5 * pass_));
    cancel = true;
  });
  auto s = session_->Solve(limits, &solution);
  canceller.join();
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->status, SolveStatus::kCancelled) << s->Describe();
  EXPECT_FALSE(s->has_plan);
  EXPECT_EQ(solution.inputs.size(), 0);
}

TEST_F(LargeSolve, ATimeLimitAfterSomePassesReturnsTheLastCompleteIterate) {
  const Eigen::VectorXd x0 = 0.5 * problem_.initial_mean;
  ASSERT_TRUE(session_->SetInitialState(x0).ok());
  SolveLimits limits;
  // Passes run slower when other tests share the cores: a limit of several passes still
  // ends after at least one complete pass.
  limits.time_limit_seconds = 4.5 * pass_;
  limits.warm_start = false;
  Solution solution;
  const auto t = Clock::now();
  auto s = session_->Solve(limits, &solution);
  const double took = Since(t);
  ASSERT_TRUE(s.ok());
  std::printf("limit %.3f s, returned after %.3f s, %d passes\n", limits.time_limit_seconds, took, s->iterations);
  EXPECT_EQ(s->status, SolveStatus::kTimeLimit) << s->Describe();
  EXPECT_TRUE(s->has_plan);
  EXPECT_GE(s->iterations, 1);
  EXPECT_TRUE(std::isfinite(s->objective));
  ASSERT_EQ(solution.inputs.rows(), problem_.horizon);
  ASSERT_EQ(solution.states.rows(), problem_.horizon + 1);
  EXPECT_TRUE(solution.inputs.allFinite() && solution.states.allFinite());
  // For this x[0]:
  EXPECT_EQ((solution.states.row(0).transpose() - x0).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_LT(took, limits.time_limit_seconds + pass_);  // within the pass it interrupted
  // The plan is the last complete iterate: the same as a solve capped at that many passes.
  SolveLimits capped;
  capped.max_iterations = s->iterations;
  capped.warm_start = false;
  Solution again;
  auto c = session_->Solve(capped, &again);
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->iterations, s->iterations);
  EXPECT_EQ((again.inputs - solution.inputs).cwiseAbs().maxCoeff(), 0.0);
}

// The next solve after an interrupted pass is the uninterrupted one: cold, then warm
// (the converged session interrupted inside its warm polish pass, which updates the
// carried regions, duals and policy).
struct Case {
  const char* instance;
  Algorithm algorithm;
  bool drop_output_bounds;  ///< IBFFD: the instance's output bounds are inactive at its optimum
  bool has_reference;       ///< J* of reference.json applies (IAKE's hard bounds are penalties)
  // 0: solve to convergence. Else a cap (IAKE converges slowly on hard bounds): the next
  // solve after an interruption is cold, so it must equal a fresh session's capped solve.
  int max_iterations = 0;
};

class NextSolve : public ::testing::TestWithParam<Case> {};

TEST_P(NextSolve, AfterAnInterruptedPassMatchesTheReference) {
  const Case c = GetParam();
  bench::BenchmarkInstance inst = LoadInstanceOrDie(c.instance);
  if (c.drop_output_bounds) {
    for (ScalarPrior& prior : inst.problem.output_priors) prior.kind = PriorKind::kNone;
  }
  SolverOptions options;
  options.algorithm = c.algorithm;
  if (c.max_iterations > 0) options.max_iterations = c.max_iterations;
  const SolveStatus done = c.max_iterations > 0 ? SolveStatus::kIterationLimit : SolveStatus::kConverged;
  auto fresh = Session::Create(inst.problem, options);
  ASSERT_TRUE(fresh.ok()) << fresh.status();
  Solution expected;
  auto e = (*fresh)->Solve(&expected);
  ASSERT_TRUE(e.ok());
  ASSERT_EQ(e->status, done) << e->Describe();
  if (c.has_reference) {
    EXPECT_NEAR(e->objective, ReferenceJ(c.instance), 1e-8 * std::abs(ReferenceJ(c.instance))) << e->Describe();
  }

  auto session = Session::Create(inst.problem, options);
  ASSERT_TRUE(session.ok());
  const double pass = OnePassSeconds(**session);
  std::printf("%s: one pass %.4f s\n", c.instance, pass);

  const auto check_next = [&](const char* what) {
    Solution next;
    auto n = (*session)->Solve(&next);
    ASSERT_TRUE(n.ok());
    EXPECT_EQ(n->status, done) << what << ": " << n->Describe();
    EXPECT_TRUE(n->has_plan);
    EXPECT_NEAR(n->objective, e->objective, 1e-9 * std::abs(e->objective)) << what;
    EXPECT_LE((next.inputs - expected.inputs).cwiseAbs().maxCoeff(),
              1e-6 * (1.0 + expected.inputs.cwiseAbs().maxCoeff()))
        << what;
  };

  // A solve interrupted inside its first pass. The pass time was measured once; on a loaded
  // machine that measurement can be long enough that half of it covers a whole pass, so a
  // solve that completed a pass is retried with a shorter limit (its result is a plan for
  // the same problem: what the next solve starts from is still a valid state).
  Solution solution;
  const auto interrupted_in_first_pass = [&](SolveLimits limits, double fraction) {
    absl::StatusOr<SolveSummary> s;
    for (; fraction > 1e-4; fraction *= 0.25) {
      limits.time_limit_seconds = fraction * pass;
      s = (*session)->Solve(limits, &solution);
      if (!s.ok() || s->iterations == 0) break;
    }
    return s;
  };

  // Cold, interrupted inside the first pass.
  SolveLimits limits;
  limits.warm_start = false;
  auto s = interrupted_in_first_pass(limits, 0.5);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->status, SolveStatus::kTimeLimit) << s->Describe();
  EXPECT_EQ(s->iterations, 0) << "not interrupted inside the first pass: " << s->Describe();
  EXPECT_FALSE(s->has_plan);
  check_next("after a cold interrupted pass");

  // Converged (or capped) and warm: the warm solve's first pass interrupted.
  limits.warm_start = true;
  s = interrupted_in_first_pass(limits, 0.3);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->status, SolveStatus::kTimeLimit) << s->Describe();
  EXPECT_EQ(s->iterations, 0) << s->Describe();
  check_next("after a warm interrupted pass");
  // And once more from the warm state the last solve left (a capped solve continues from
  // there: another plan).
  if (c.max_iterations == 0) check_next("warm after that");
}

INSTANTIATE_TEST_SUITE_P(Instances, NextSolve,
                         ::testing::Values(Case{"masses_N30000", Algorithm::kIffbdd, false, true},
                                           Case{"random_outbox_M40_K20_L20_N1000_s1", Algorithm::kIffbdd, false, true},
                                           Case{"masses_N30000", Algorithm::kIbffd, true, false},
                                           Case{"masses_N30000", Algorithm::kIake, false, false, 12}),
                         [](const auto& info) {
                           std::string name =
                               std::string(AlgorithmName(info.param.algorithm)) + "_" + std::to_string(info.index);
                           return name;
                         });

}  // namespace
}  // namespace nupmpc::core
