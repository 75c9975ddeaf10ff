#ifndef NUPMPC_CLIENT_SESSION_ROUTING_H_
#define NUPMPC_CLIENT_SESSION_ROUTING_H_

// The client's half of the routing contract for several replicas behind one balancer (the
// proto's comment above MpcService): every call addressed by a session id carries the id
// in the x-nupmpc-session header, which the balancer hashes onto a replica, and the client
// draws the ids of the sessions it creates so that CreateSession can carry the header too.

#include <string>

#include "grpcpp/grpcpp.h"

namespace nupmpc {

inline constexpr char kSessionHeader[] = "x-nupmpc-session";

// 32 lower-case hex digits: 128 bits from the OS's random source (as the server draws its
// own ids), so ids drawn by independent clients do not collide.
std::string NewSessionId();

// Adds the routing header for `session_id` to a call (nothing for a malformed id).
void RouteToSession(grpc::ClientContext* context, const std::string& session_id);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_SESSION_ROUTING_H_
