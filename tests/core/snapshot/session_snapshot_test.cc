// Session snapshots: a restored session continues bit-identically (snapshot_oracle.h) for
// every algorithm on the benchmark instances, with updates applied before the snapshot,
// after a compaction and after an interrupted solve.

#include <memory>
#include <string>
#include <vector>

#include "core/examples/scenarios/dac.h"
#include "core/session/session.h"
#include "gtest/gtest.h"
#include "tests/core/snapshot/snapshot_oracle.h"
#include "tests/util/benchmark_files.h"

namespace nupmpc::core {
namespace {

using ::nupmpc::testing::ExpectRestoredTwinsMatch;
using ::nupmpc::testing::LoadInstanceOrDie;
using ::nupmpc::testing::OracleRun;
using ::nupmpc::testing::SessionFactory;

// A factory of sessions of `problem` under `options`; null when the algorithm does not
// apply to the problem (the caller skips that pair).
SessionFactory SessionsOf(const Problem& problem, const SolverOptions& options) {
  if (!Session::Create(problem, options).ok()) return nullptr;
  return [problem, options]() -> std::unique_ptr<MpcSession> {
    absl::StatusOr<std::unique_ptr<Session>> s = Session::Create(problem, options);
    EXPECT_TRUE(s.ok()) << s.status();
    return s.ok() ? *std::move(s) : nullptr;
  };
}

// What a client changes between steps besides x[0]: new references and a tighter input
// bound (step 2), a model term that becomes per-step (step 4: the algorithm is built again
// for the new storage), receding references (step 6).
void ClientUpdates(int step, const MpcSession& session, StepUpdate* update) {
  const Problem& p = session.problem();
  if (step == 2) {
    ComponentPriors output{.index = 0, .priors = {}};
    for (int n = 0; n <= p.horizon; ++n) {
      ScalarPrior prior = p.output_prior(n, 0);
      if (prior.has_gaussian()) prior.mean += 0.05;
      output.priors.push_back(prior);
    }
    update->outputs.push_back(std::move(output));
    ComponentPriors input{.index = 0, .priors = {}};
    for (int n = 0; n < p.horizon; ++n) {
      ScalarPrior prior = p.input_prior(n, 0);
      if (prior.kind == PriorKind::kBox) prior.upper -= 0.1 * (prior.upper - prior.lower);
      input.priors.push_back(prior);
    }
    update->inputs.push_back(std::move(input));
  }
  if (step == 4) update->model.A.push_back({.step = 0, .value = p.A_at(0) * (1.0 + 1e-3)});
  if (step == 6) update->shift = true;
}

OracleRun LoopOf(const bench::BenchmarkInstance& inst, int steps) {
  OracleRun run;
  run.steps = steps;
  run.first_state = inst.problem.initial_mean;
  return run;
}

constexpr Algorithm kAlgorithms[] = {Algorithm::kAuto, Algorithm::kIake, Algorithm::kIbffd, Algorithm::kIffbdd};

// One benchmark instance under one algorithm (forced, or the automatic choice).
struct Case {
  const char* instance;
  Algorithm algorithm;
  int max_iterations = 0;    ///< 0: the default (IAKE's slow convergence is capped on the large ones)
  double disturbance = 0.0;  ///< OracleRun::disturbance
};

class BenchmarkSnapshot : public ::testing::TestWithParam<Case> {};

TEST_P(BenchmarkSnapshot, RestoredTwinsGiveBitIdenticalPlans) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie(GetParam().instance);
  SolverOptions options;
  options.algorithm = GetParam().algorithm;
  if (GetParam().max_iterations > 0) options.max_iterations = GetParam().max_iterations;
  const SessionFactory make = SessionsOf(inst.problem, options);
  ASSERT_TRUE(make) << "the algorithm does not apply";
  OracleRun run = LoopOf(inst, 9);
  run.snapshot_before = {1, 3, 5, 7};
  run.extra = ClientUpdates;
  run.disturbance = GetParam().disturbance;
  EXPECT_GE(ExpectRestoredTwinsMatch(make, run, GetParam().instance), 9);
}

INSTANTIATE_TEST_SUITE_P(
    Instances, BenchmarkSnapshot,
    ::testing::Values(Case{"masses_N30", Algorithm::kAuto}, Case{"masses_N30", Algorithm::kIake, 300},
                      Case{"masses_N30", Algorithm::kIffbdd}, Case{"masses_N300", Algorithm::kAuto},
                      Case{"masses_N300", Algorithm::kIake, 60}, Case{"masses_N300", Algorithm::kIffbdd},
                      Case{"ibffd_2d_N100", Algorithm::kAuto}, Case{"ibffd_2d_N100", Algorithm::kIake, 100},
                      Case{"ibffd_2d_N100_hinge", Algorithm::kAuto}, Case{"ibffd_2d_N100_hinge", Algorithm::kIake, 100},
                      Case{"corridor_N175", Algorithm::kAuto}, Case{"corridor_N175", Algorithm::kIake, 100},
                      Case{"corridor_N175", Algorithm::kIffbdd}, Case{"masses_N30", Algorithm::kAuto, 0, 0.05},
                      Case{"masses_N300", Algorithm::kAuto, 0, 0.05}, Case{"ibffd_2d_N100", Algorithm::kAuto, 0, 0.05},
                      Case{"ibffd_2d_N100_hinge", Algorithm::kAuto, 0, 0.05},
                      Case{"corridor_N175", Algorithm::kAuto, 0, 0.02}),
    [](const ::testing::TestParamInfo<Case>& info) {
      return std::string(info.param.instance) + "_" + AlgorithmName(info.param.algorithm) +
             (info.param.disturbance > 0.0 ? "_disturbed" : "");
    });

TEST(SessionSnapshot, AdaptedDualScalesRestoreBitIdentically) {
  // IFFBDD adapts γ of half-spaces and soft bounds (hard boxes keep (b-a)/2): masses_N30
  // with its output boxes made one-sided and its input boxes soft, disturbed so that warm
  // solves iterate.
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  Problem p = inst.problem;
  for (ScalarPrior& prior : p.output_priors) {
    if (prior.kind == PriorKind::kBox) prior.kind = PriorKind::kAtMost;
  }
  for (ScalarPrior& prior : p.input_priors) {
    if (prior.kind == PriorKind::kBox) prior.slope = 5.0;
  }
  SolverOptions options;
  options.algorithm = Algorithm::kIffbdd;
  options.max_iterations = 1000;  // some steps find no feasible point: capped for the test's time
  const SessionFactory make = SessionsOf(p, options);
  ASSERT_TRUE(make);
  OracleRun run = LoopOf(inst, 9);
  run.snapshot_before = {1, 3, 5, 7};
  run.disturbance = 1.0;
  run.extra = ClientUpdates;
  EXPECT_EQ(ExpectRestoredTwinsMatch(make, run, "masses_N30 one-sided"), 11);
}

TEST(SessionSnapshot, RandomOutboxRestoresBitIdentically) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("random_outbox_M40_K20_L20_N1000_s1");
  const SessionFactory make = SessionsOf(inst.problem, {});
  ASSERT_TRUE(make);
  OracleRun run = LoopOf(inst, 4);  // N = 1000, M = 40: a few steps (about 25 s under ASan)
  run.snapshot_before = {1, 2};
  EXPECT_EQ(ExpectRestoredTwinsMatch(make, run, "random_outbox"), 5);
}

TEST(SessionSnapshot, ACompactedSessionRestoresIntoAFreshOne) {
  for (const char* name : {"masses_N30", "ibffd_2d_N100_hinge", "corridor_N175"}) {
    const bench::BenchmarkInstance inst = LoadInstanceOrDie(name);
    for (Algorithm algorithm : kAlgorithms) {
      SolverOptions options;
      options.algorithm = algorithm;
      OracleRun run = LoopOf(inst, 7);
      run.release_before_snapshot = true;
      run.extra = ClientUpdates;
      if (algorithm == Algorithm::kIake) options.max_iterations = 60;
      const SessionFactory make = SessionsOf(inst.problem, options);
      if (!make) continue;
      const std::string label = std::string(name) + "/" + AlgorithmName(algorithm) + " compacted";
      EXPECT_GE(ExpectRestoredTwinsMatch(make, run, label), 7) << label;
    }
  }
}

TEST(SessionSnapshot, ASnapshotAfterAnInterruptedSolveRestores) {
  for (const char* name : {"corridor_N175", "masses_N300"}) {
    const bench::BenchmarkInstance inst = LoadInstanceOrDie(name);
    const SessionFactory make = SessionsOf(inst.problem, {});
    ASSERT_TRUE(make);
    OracleRun run = LoopOf(inst, 7);
    run.snapshot_before = {3};
    // Step 2 stops within its passes (only A runs it): the carried state it leaves is
    // what the snapshot holds.
    run.limits_at = [](int step) {
      SolveLimits limits;
      if (step == 2) limits.time_limit_seconds = 2e-4;
      return limits;
    };
    EXPECT_EQ(ExpectRestoredTwinsMatch(make, run, std::string(name) + " interrupted"), 3);
  }
}

TEST(SessionSnapshot, BinaryInputsRestoreBitIdentically) {
  const Problem p = examples::DacWindow(40, 1e-2, 0, 2.0);
  SolverOptions options;
  options.max_iterations = 200;
  const SessionFactory make = SessionsOf(p, options);
  ASSERT_TRUE(make);
  OracleRun run;
  run.steps = 6;
  run.snapshot_before = {1, 3};
  run.first_state = p.initial_mean;
  run.extra = [](int step, const MpcSession&, StepUpdate* update) { update->shift = step > 0; };
  EXPECT_EQ(ExpectRestoredTwinsMatch(make, run, "dac binary"), 6);
}

}  // namespace
}  // namespace nupmpc::core
