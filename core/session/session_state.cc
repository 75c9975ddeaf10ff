// Session snapshots (MpcSession::SaveState/RestoreState): the problem's current values,
// restored through the path an update takes, then the state the next solve starts from.

#include <string>
#include <utility>

#include "core/algorithms/outer_iteration.h"
#include "core/session/session.h"
#include "core/snapshot/problem_state.h"
#include "core/snapshot/state_archive.h"
#include "core/util/status_macros.h"

namespace nupmpc::core {

absl::Status Session::SaveState(std::string* out) {
  StateWriter writer(out);
  PersistState(writer);
  return writer.status();
}

absl::Status Session::RestoreState(std::string_view bytes) {
  StateReader reader(bytes);
  PersistState(reader);
  return reader.status();
}

void Session::PersistState(StateArchive& archive) {
  archive.BeginSection("session");
  if (archive.restoring()) {
    Problem values = problem_;  // the shape of this session's problem, overwritten
    PersistProblemValues(archive, values);
    if (!archive.ok()) return;
    if (absl::Status adopted = AdoptRestoredValues(std::move(values)); !adopted.ok()) {
      return archive.Fail("problem", std::string(adopted.message()));
    }
  } else {
    PersistProblemValues(archive, problem_);
  }
  // The values select the algorithm (or the options force it); a snapshot whose carried
  // state belongs to another one was taken under other options.
  Algorithm algorithm = algorithm_->algorithm();
  archive.Enumerator("algorithm", algorithm, Algorithm::kAuto, Algorithm::kIffbdd);
  if (archive.restoring() && archive.ok() && algorithm != algorithm_->algorithm()) {
    return archive.Fail("algorithm", "the restored values run another algorithm here (other options?)");
  }
  archive.Flag("has_warm_state", has_warm_state_);
  // The carried plan: the first pass of a warm solve compares its iterate with it
  // (whether a non-convex problem's plan settled), and the shift moves it.
  archive.Field("best_x0", best_.x0);
  archive.Field("best_u", best_.u);
  algorithm_->PersistState(archive, problem_);
  archive.EndSection();
}

absl::Status Session::AdoptRestoredValues(Problem values) {
  NUPMPC_RETURN_IF_ERROR(Validate(values));
  bool was_input_constrained = false;
  for (const ScalarPrior& prior : problem_.input_priors) was_input_constrained |= prior.kind != PriorKind::kNone;
  // An update that made a model term per-step rebuilt the algorithm for that storage.
  const bool new_storage = values.A.size() != problem_.A.size() || values.B.size() != problem_.B.size() ||
                           values.C.size() != problem_.C.size();
  Problem previous = std::exchange(problem_, std::move(values));
  absl::Status adopted = AdoptNewValues(was_input_constrained, new_storage);
  if (!adopted.ok()) problem_ = std::move(previous);
  return adopted;
}

}  // namespace nupmpc::core
