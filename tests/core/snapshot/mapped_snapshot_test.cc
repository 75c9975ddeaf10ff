// Snapshots of the sessions around a Session: input differences (u[-1] carried),
// multi-level inputs (binaries) and keep-out regions (the linearised session and the next
// linearisation point). The oracle of snapshot_oracle.h: restored twins plan bit-identically.

#include <memory>
#include <string>
#include <vector>

#include "core/examples/scenarios/obstacle_avoidance.h"
#include "core/nonlinear/keep_out_session.h"
#include "core/session/input_mapped_session.h"
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

SessionFactory MappedSessionsOf(const Problem& base, const InputMap& map, const SolverOptions& options) {
  return [base, map, options]() -> std::unique_ptr<MpcSession> {
    absl::StatusOr<Problem> mapped = MapInputs(base, map);
    EXPECT_TRUE(mapped.ok()) << mapped.status();
    if (!mapped.ok()) return nullptr;
    absl::StatusOr<std::unique_ptr<Session>> inner = Session::Create(*std::move(mapped), options);
    EXPECT_TRUE(inner.ok()) << inner.status();
    if (!inner.ok()) return nullptr;
    return InputMappedSession::Wrap(*std::move(inner), map, DimensionsOf(base));
  };
}

// New output references (step 2), a given u[-1] (step 3, input differences only: the
// session's own default is the last plan's u[0]), receding references (step 5).
void MappedUpdates(int step, const MpcSession& session, StepUpdate* update, bool differences) {
  const Dimensions d = session.dimensions();
  if (step == 2) {
    ComponentPriors output{.index = 0, .priors = {}};
    for (int n = 0; n <= d.horizon; ++n) {
      ScalarPrior prior = session.problem().output_prior(n, 0);
      if (prior.has_gaussian()) prior.mean += 0.05;
      output.priors.push_back(prior);
    }
    update->outputs.push_back(std::move(output));
  }
  if (step == 3 && differences) update->previous_input = Eigen::VectorXd::Constant(d.num_inputs, 0.01);
  if (step == 5) update->shift = true;
}

TEST(MappedSnapshot, InputDifferencesCarryThePreviousInput) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  InputMap map;
  map.differences = true;
  map.difference_priors.assign(static_cast<std::size_t>(inst.problem.horizon) * inst.problem.num_inputs,
                               ScalarPrior::Box(-0.5, 0.5).WithGaussian(0.0, 10.0));
  map.previous_input = Eigen::VectorXd::Constant(inst.problem.num_inputs, 0.05);
  for (bool compacted : {false, true}) {
    OracleRun run;
    run.steps = 8;
    run.first_state = inst.problem.initial_mean;
    run.release_before_snapshot = compacted;
    run.extra = [](int step, const MpcSession& s, StepUpdate* u) { MappedUpdates(step, s, u, true); };
    SolverOptions options;
    options.max_iterations = 300;
    EXPECT_EQ(ExpectRestoredTwinsMatch(MappedSessionsOf(inst.problem, map, options), run,
                                       compacted ? "delta-u compacted" : "delta-u"),
              9);
  }
}

TEST(MappedSnapshot, MultiLevelInputsRestoreBitIdentically) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  Problem base = inst.problem;
  for (int n = 0; n < base.horizon; ++n) base.mutable_input_prior(n, 0) = ScalarPrior::Free();
  InputMap map;
  map.levels.assign(base.num_inputs, InputLevels{});
  map.levels[0] = {.count = 3, .lowest = -0.5, .spacing = 0.5};
  SolverOptions options;
  options.max_iterations = 100;  // IAKE, for the binaries: capped for the test's time
  OracleRun run;
  run.steps = 8;
  run.first_state = base.initial_mean;
  run.extra = [](int step, const MpcSession& s, StepUpdate* u) { MappedUpdates(step, s, u, false); };
  EXPECT_EQ(ExpectRestoredTwinsMatch(MappedSessionsOf(base, map, options), run, "3-level"), 9);
}

TEST(MappedSnapshot, KeepOutSessionsRestoreBitIdentically) {
  constexpr int kHorizon = 30;
  KeepOut keep_out;
  keep_out.regions = examples::MixedShapesScene(kInfinity);
  const SessionFactory make = [keep_out]() -> std::unique_ptr<MpcSession> {
    absl::StatusOr<std::unique_ptr<KeepOutSession>> s =
        KeepOutSession::Create(examples::ObstaclePlant(kHorizon), keep_out);
    EXPECT_TRUE(s.ok()) << s.status();
    return s.ok() ? *std::move(s) : nullptr;
  };
  for (bool compacted : {false, true}) {
    OracleRun run;
    run.steps = 8;
    run.snapshot_before = {0, 1, 3, 5};  // also before the first solve (no plan yet)
    run.first_state = examples::ObstaclePlant(kHorizon).initial_mean;
    run.release_before_snapshot = compacted;
    run.extra = [](int step, const MpcSession& s, StepUpdate* u) { MappedUpdates(step, s, u, false); };
    EXPECT_EQ(ExpectRestoredTwinsMatch(make, run, compacted ? "keep-out compacted" : "keep-out"), 12);
  }
}

}  // namespace
}  // namespace nupmpc::core
