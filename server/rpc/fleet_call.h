#ifndef NUPMPC_SERVER_RPC_FLEET_CALL_H_
#define NUPMPC_SERVER_RPC_FLEET_CALL_H_

// SolveFleet: many sessions' steps in one call (SolveFleetRequest in the .proto), solved in
// parallel on the workers, each answered on its own, the call answered once all are done.
//
// The steps are shared out by at most worker_threads runner tasks on the pool (so one call
// takes at most that many queue places, however many steps it has). A runner solves a
// step right where it is when the step's session is idle; a session that is busy (a step
// of an earlier call, a unary Solve) gets the step through its strand, where it waits
// without holding the runner. Newest state wins per session through a ticket: every
// accepted fleet step of a session takes the next number, and a step that finds a higher
// number taken is answered SUPERSEDED without touching the session: when a runner takes it
// (so of repeated entries in one call only the last waits for the session), when it would
// start, and while it waits, as soon as a newer step is submitted to the session's strand
// (so stale steps never fill the session's wait bound and get the newest refused).

#include "nupmpc/v1/nupmpc.pb.h"
#include "server/auth/caller.h"
#include "server/rpc/unary_call.h"

namespace nupmpc::server {

using FleetCall = UnaryCall<v1::SolveFleetRequest, v1::SolveFleetResponse>;

// Checks the request, accepts its steps for `caller` and starts them; `call` is answered
// when the last step is.
void StartFleet(FleetCall* call, const Caller& caller);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_RPC_FLEET_CALL_H_
