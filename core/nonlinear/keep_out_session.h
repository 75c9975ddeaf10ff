#ifndef NUPMPC_CORE_NONLINEAR_KEEP_OUT_SESSION_H_
#define NUPMPC_CORE_NONLINEAR_KEEP_OUT_SESSION_H_

// A receding-horizon session for a linear plant with keep-out regions
// (core/nonlinear/keep_out.h): each Solve() runs sequential linearisation starting from
// the previous plan (shifted by ShiftWarmStart()), and the first linearised problem
// continues the previous solve's NUP state, so a controller that moves a little per period
// needs a few passes, not a cold solve. The caller sees the plant's problem and plant's
// outputs only; the region outputs are internal.

#include <memory>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "core/nonlinear/keep_out.h"
#include "core/nonlinear/sequential_solver.h"
#include "core/session/mpc_session.h"
#include "core/session/session.h"
#include "core/snapshot/state_archive.h"

namespace nupmpc::core {

class KeepOutSession final : public MpcSession {
 public:
  // INVALID_ARGUMENT naming the field for a bad plant, bad regions or bad options.
  static absl::StatusOr<std::unique_ptr<KeepOutSession>> Create(Problem plant, KeepOut keep_out,
                                                                SolverOptions solver_options = {},
                                                                SequentialOptions options = {});

  // The plant's problem is the free planner's (it is kept current for cold starts).
  const Problem& problem() const override { return free_planner_->problem(); }
  Algorithm algorithm() const override { return solver_->algorithm(); }
  const KeepOut& keep_out() const { return keep_out_; }

  absl::Status SetInitialState(const Eigen::VectorXd& x0) override;
  // The free planner holds the plant's problem: it checks and applies the update; the
  // linearisation then takes the plant's new priors.
  absl::Status Apply(const StepUpdate& update) override;
  absl::Status Update(const Problem& plant);
  void ShiftWarmStart() override;
  void ReleaseWorkspace() override { solver_->ReleaseWorkspace(); }

  // limits.max_iterations (0: the solver options' max_iterations) caps the passes over
  // all linearisations, so one solve costs at most what a linear session's would.
  // The summary is the last linearised problem's, with iterations counted over all
  // linearisations, `linearisations` and `nonlinear_violation` set, max_violation
  // including the hard regions' intrusion, and status ITERATION_LIMIT when the inner solves
  // converged but the linearisations did not settle within the sequential options' cap.
  absl::StatusOr<SolveSummary> Solve(const SolveLimits& limits, Solution* solution) override;

  // The plant's values (the free planner's snapshot), the linearised session's, and the
  // next linearisation point.
  absl::Status SaveState(std::string* out) override;
  absl::Status RestoreState(std::string_view bytes) override;

 private:
  KeepOutSession(KeepOut keep_out, std::unique_ptr<SequentialSolver> solver, std::unique_ptr<Session> free_planner,
                 int max_iterations);
  // The cold start: the plan without regions (straight through them). Linearising there
  // keeps the path's shape; linearising at rest (every point at x[0]) cut the plane with
  // tangents facing x[0] and took a hundred linearisations to settle on the test scene.
  // True when it planned; false (with the free planner's summary in `stopped`) when the
  // limits stopped it before a first plan.
  absl::StatusOr<bool> PlanWithoutRegions(const SolveLimits& limits, SolveSummary* stopped);
  // Snapshots: both directions; the inner sessions' bytes travel in `planner` and
  // `linearised`.
  void PersistState(StateArchive& archive, std::string& planner, std::string& linearised);

  KeepOut keep_out_;
  bool all_regions_hard_ = true;
  int max_iterations_;  ///< default cap on passes per Solve(), over all linearisations
  std::unique_ptr<SequentialSolver> solver_;
  // The plant alone, for cold starts; its scratch is released after each use (cold
  // starts are rare in a session's life).
  std::unique_ptr<Session> free_planner_;
  Solution guess_;  ///< the next linearisation point: the previous plan (shifted)
  bool has_plan_ = false;
  Solution plan_;  ///< the linearised problem's plan (plant outputs + region outputs)
};

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_NONLINEAR_KEEP_OUT_SESSION_H_
