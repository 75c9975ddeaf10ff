#ifndef NUPMPC_CLIENT_SPEC_UPDATE_H_
#define NUPMPC_CLIENT_SPEC_UPDATE_H_

// What an answered Step leaves in the server's session, written back into the spec the
// session was created from, so that a client that has to re-create the session (after a
// server restart) gets the session the server had, not the one it started with.
//
// This is the client's mirror of the server's step semantics (server/sessions/step_solver.cc
// SolveStep and what it calls; the proto's Step, PriorUpdate and InputDifferences
// comments): change one, change the other, and tests/server/service/reconnect_fidelity_test.cc
// checks that they still agree. Proto only: the client never includes core/ or server/.

#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc {

// Applies `step`, answered with `result`, to `spec`. Call it only for a step the server
// accepted (an answer, not an error): a rejected step changes nothing on the server.
//  * state: replaces initial_state.mean (empty keeps it).
//  * update (non-GP sessions): with shift, every per-step array of input_priors,
//    output_priors and input_differences.priors moves one step (n+1 → n, the last
//    repeated; length-1 arrays are constant), then the listed components replace the
//    spec's.
//  * reference (GP sessions): replaces gp.reference.
//  * model: with shift, every per-step model term moves one step (n+1 → n, the last
//    repeated); then state_offsets / output_offsets replace the affine terms of every
//    step; then the listed steps' a, b, c, state_offset, output_offset replace theirs
//    (a term stored once becomes one per step first).
//  * input_differences: u[-1] of the next step is the plan's u[0] when the result has a
//    plan (whatever previous_input this step sent); without a plan it stays.
//  * A SUPERSEDED result: nothing of the step was applied, nothing changes.
void ApplyStepToSpec(const v1::Step& step, const v1::SolveResult& result, v1::ProblemSpec* spec);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_SPEC_UPDATE_H_
