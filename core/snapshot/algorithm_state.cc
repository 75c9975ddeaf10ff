// What each algorithm carries from one solve to the next, for snapshots (the
// PersistState members of the algorithms, in one place so the carried state can be read
// and reviewed together). Per-pass scratch (filter and smoother messages, polish regions,
// the interior point's iterates) is not saved: every pass or solve writes it before
// reading it.

#include <limits>

#include "core/algorithms/iake.h"
#include "core/algorithms/ibffd.h"
#include "core/algorithms/ibffd_policy.h"
#include "core/algorithms/iffbdd.h"
#include "core/algorithms/iffbdd_input_polish.h"
#include "core/algorithms/outer_iteration.h"
#include "core/snapshot/state_archive.h"

namespace nupmpc::core {
namespace {

// Far beyond any horizon (a shift moves every step by one), and n + shifts never overflows.
constexpr int kMaxShifts = 1 << 30;

// Whether the workspace is held, made equal on restore by `release` or `acquire`: a
// released policy is recomputed on acquiring, and that recomputation must happen in the
// restored session exactly when it would have in the original.
template <class Release, class Acquire>
void PersistWorkspaceHeld(StateArchive& archive, bool held_now, Release release, Acquire acquire) {
  bool held = held_now;
  archive.Flag("workspace_held", held);
  if (!archive.restoring() || !archive.ok() || held == held_now) return;
  if (held) {
    acquire();
  } else {
    release();
  }
}

}  // namespace

void ActiveSetIteration::PersistRegions(StateArchive& archive) {
  archive.EnumeratorField("region", region_, Region::kBelow, Region::kAbove);
  archive.Flag("has_regions", has_regions_);
}

void Iake::PersistState(StateArchive& archive, const Problem& problem) {
  archive.BeginSection("iake");
  PersistWorkspaceHeld(
      archive, workspace_held_, [this] { ReleaseWorkspace(); }, [&] { AcquireWorkspace(problem); });
  archive.Field("input_nup", input_nup_);
  archive.Field("row_nup", row_nup_);
  // Pins live within a solve; saved anyway, as Iterate() reads them.
  archive.Field("pinned_value", pinned_value_);
  archive.EndSection();
}

void IbffdPolicy::PersistState(StateArchive& archive) {
  archive.BeginSection("policy");
  PersistWorkspaceHeld(
      archive, xi_step_.size() != 0, [this] { ReleaseWorkspace(); }, [this] { AllocateWorkspace(); });
  archive.Flag("has_policy", has_policy_);
  archive.Flag("policy_released", policy_released_);
  archive.EnumeratorField("policy_region", policy_region_, Region::kBelow, Region::kAbove);
  archive.Integer("policy_shifts", policy_shifts_, 0, kMaxShifts);
  // Read by IFFBDD's first polish call of a solve, before this solve's first pass of the
  // sub-problem writes it: the last solve's verdict carries over.
  archive.Flag("outputs_outside", outputs_outside_);
  // A live policy's gains and offsets, as computed (after new weights a recomputation
  // would give other gains: the original goes on with these).
  if (has_policy_) {
    archive.Field("W_step", W_step_);
    archive.Field("xi_step", xi_step_);
  }
  archive.EndSection();
}

void Ibffd::PersistState(StateArchive& archive, const Problem& /*problem*/) {
  archive.BeginSection("ibffd");
  archive.Field("nup", nup_);
  archive.Field("slope", slope_);
  PersistRegions(archive);
  policy_.PersistState(archive);
  archive.EndSection();
}

void IffbddInputPolish::PersistState(StateArchive& archive) {
  archive.BeginSection("input_polish");
  bool held = policy_ != nullptr;
  archive.Flag("held", held);
  if (archive.restoring() && archive.ok() && held != (policy_ != nullptr)) {
    archive.Fail("held", "the input polish is not held as in the saved session");
  } else if (policy_ != nullptr) {
    policy_->PersistState(archive);
  } else {
    archive.Flag("memory_valid", released_.valid);
    if (released_.valid) {
      if (archive.restoring()) released_.regions.resize(input_row_.size());
      archive.EnumeratorField("memory_regions", released_.regions, Region::kBelow, Region::kAbove);
      archive.Integer("memory_shifts", released_.shifts, 0, kMaxShifts);
    }
  }
  archive.EndSection();
}

void Iffbdd::PersistState(StateArchive& archive, const Problem& problem) {
  archive.BeginSection("iffbdd");
  PersistWorkspaceHeld(
      archive, workspace_held_, [this] { ReleaseWorkspace(); }, [&] { AcquireWorkspace(problem); });
  archive.Field("nup", nup_);
  archive.Field("gamma", gamma_);
  PersistRegions(archive);
  archive.Field("step_costate", step_costate_);
  archive.Field("row_dual", row_dual_);
  archive.Flag("has_duals", has_duals_);
  input_polish_.PersistState(archive);
  // The interior point's iterates belong to one solve for one x[0]: a new x[0] or a shift
  // forgets them (RefreshInitialState, ShiftWarmStart), and a warm solve adopts the carried
  // regions, which switches to the dual iteration anyway.
  if (archive.restoring()) interior_point_.ForgetSolve();
  archive.EndSection();
}

}  // namespace nupmpc::core
