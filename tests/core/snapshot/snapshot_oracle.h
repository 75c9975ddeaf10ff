#ifndef NUPMPC_TESTS_CORE_SNAPSHOT_SNAPSHOT_ORACLE_H_
#define NUPMPC_TESTS_CORE_SNAPSHOT_SNAPSHOT_ORACLE_H_

// The bit-identity oracle of session snapshots: a closed loop on session A (x[0] from the
// previous plan, the step's update, solve, shift); before some steps A is saved and a
// fresh session B, built from the same creation spec, restores the bytes; B then runs the
// next steps beside A with the same updates. Their plans must be bit-identical (the raw
// doubles) and take the same passes: anything carried that a snapshot dropped shows up as
// another pass count or another rounding.

#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "core/session/mpc_session.h"
#include "gtest/gtest.h"

namespace nupmpc::testing {

using SessionFactory = std::function<std::unique_ptr<core::MpcSession>()>;
// The step's update besides x[0] (new references, bounds, model terms...); may be empty.
using ExtraUpdate = std::function<void(int step, const core::MpcSession& session, core::StepUpdate* update)>;

struct OracleRun {
  int steps = 8;
  std::set<int> snapshot_before = {1, 3, 5};  ///< steps before which A is saved
  int compared_steps = 3;
  Eigen::VectorXd first_state;           ///< x[0] of step 0 (later: the last plan's x[1])
  ExtraUpdate extra;                     ///< may be null
  bool release_before_snapshot = false;  ///< A is compacted (ReleaseWorkspace) first
  // The plant is not the model: the next x[0] is the plan's x[1] moved by this fraction of
  // its size (deterministic), so warm solves have a new active set to find and iterate
  // with their carried NUP state instead of confirming the carried active set at once.
  double disturbance = 0.0;
  // The limits of A's solve at a step (null: none): a step interrupted by them must not be
  // one B runs beside A (its pass count depends on the wall clock).
  std::function<core::SolveLimits(int step)> limits_at;
};

inline bool BitIdentical(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
}

// Runs the oracle; returns how many (snapshot, step) pairs were compared.
inline int ExpectRestoredTwinsMatch(const SessionFactory& make, const OracleRun& run, const std::string& label) {
  std::unique_ptr<core::MpcSession> a = make();
  if (a == nullptr) {
    ADD_FAILURE() << label << ": no session";
    return 0;
  }
  struct Twin {
    std::unique_ptr<core::MpcSession> session;
    int from_step;
  };
  std::vector<Twin> twins;
  Eigen::VectorXd x0 = run.first_state;
  int compared = 0;
  for (int k = 0; k < run.steps; ++k) {
    if (run.snapshot_before.count(k) > 0) {
      if (run.release_before_snapshot) a->ReleaseWorkspace();
      std::string bytes;
      EXPECT_TRUE(a->SaveState(&bytes).ok()) << label;
      std::unique_ptr<core::MpcSession> b = make();
      const absl::Status restored = b->RestoreState(bytes);
      EXPECT_TRUE(restored.ok()) << label << " before step " << k << ": " << restored;
      if (restored.ok()) twins.push_back({std::move(b), k});
    }
    core::StepUpdate update;
    update.state = x0;
    if (run.extra) run.extra(k, *a, &update);
    const core::SolveLimits limits = run.limits_at ? run.limits_at(k) : core::SolveLimits{};
    EXPECT_TRUE(a->Apply(update).ok()) << label << " step " << k;
    core::Solution plan;
    absl::StatusOr<core::SolveSummary> solved = a->Solve(limits, &plan);
    EXPECT_TRUE(solved.ok()) << label << " step " << k;
    if (!solved.ok()) return compared;
    for (Twin& twin : twins) {
      const std::string where =
          label + ", snapshot before step " + std::to_string(twin.from_step) + ", step " + std::to_string(k);
      EXPECT_TRUE(twin.session->Apply(update).ok()) << where;
      core::Solution twin_plan;
      absl::StatusOr<core::SolveSummary> twin_solved = twin.session->Solve(limits, &twin_plan);
      EXPECT_TRUE(twin_solved.ok()) << where;
      if (!twin_solved.ok()) continue;
      EXPECT_EQ(twin_solved->iterations, solved->iterations) << where;
      EXPECT_EQ(twin_solved->status, solved->status) << where;
      EXPECT_EQ(twin_solved->warm_started, solved->warm_started) << where;
      EXPECT_TRUE(BitIdentical(twin_plan.inputs, plan.inputs))
          << where << ": plans differ by "
          << (twin_plan.inputs.rows() == plan.inputs.rows() && twin_plan.inputs.cols() == plan.inputs.cols()
                  ? (twin_plan.inputs - plan.inputs).norm()
                  : -1.0);
      EXPECT_TRUE(BitIdentical(twin_plan.states, plan.states)) << where;
      twin.session->ShiftWarmStart();
      ++compared;
    }
    std::erase_if(twins, [&](const Twin& t) { return k + 1 - t.from_step >= run.compared_steps; });
    a->ShiftWarmStart();
    if (plan.states.rows() > 1) {
      x0 = plan.states.row(1).transpose();
      for (Eigen::Index i = 0; i < x0.size(); ++i) {
        x0(i) += run.disturbance * (std::abs(x0(i)) + 0.1) * std::sin(1.3 * k + 0.7 * static_cast<double>(i));
      }
    }
  }
  return compared;
}

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_CORE_SNAPSHOT_SNAPSHOT_ORACLE_H_
