#ifndef NUPMPC_CORE_SNAPSHOT_PROBLEM_STATE_H_
#define NUPMPC_CORE_SNAPSHOT_PROBLEM_STATE_H_

// The values of a Problem in a snapshot: everything a client can change after creation
// (x[0], the priors with their references and bounds, the model terms, the terminal cost).
// The dimensions and the horizon are the receiving session's (its creation spec); the
// number of matrices of each model term may differ (an update can make a term per-step),
// within the counts a Problem allows. A restore writes into `problem` without checking
// the values: the caller adopts them through the path an update takes (validation
// included), so restored values are trusted no more than updated ones.

#include "core/problem.h"
#include "core/snapshot/state_archive.h"

namespace nupmpc::core {

void PersistProblemValues(StateArchive& archive, Problem& problem);

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_SNAPSHOT_PROBLEM_STATE_H_
