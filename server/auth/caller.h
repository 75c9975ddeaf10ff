#ifndef NUPMPC_SERVER_AUTH_CALLER_H_
#define NUPMPC_SERVER_AUTH_CALLER_H_

// Who made a call, and what that caller may do with a session: sessions belong to the
// principal that created them (server/auth/auth_processor.h identifies it).

#include <string>

#include "grpcpp/server_context.h"
#include "server/auth/auth_processor.h"

namespace nupmpc::server {

// The principal of a call that authentication would refuse now (its token was removed
// between the processor's check and the handler): never a token's or a certificate's, so
// it owns nothing and reaches nothing.
inline constexpr char kNobody[] = " nobody";

struct Caller {
  std::string principal;   ///< empty: authentication is off
  bool admin = false;      ///< may see and close every session
  bool by_token = false;   ///< authenticated by a bearer token (revoked with it), not a certificate
  std::string connection;  ///< the peer address (one per client connection)

  bool authenticated() const { return !principal.empty(); }
};

// The caller of `context`'s call, identified from the call's own metadata by `auth` (null:
// authentication is off, the caller has no principal).
Caller CallerOf(const grpc::ServerContextBase& context, const AuthProcessor* auth);

// What a session records of the caller that created it.
struct SessionOwner {
  std::string principal;   ///< empty when created without authentication
  std::string connection;  ///< the creating call's peer
};
inline SessionOwner OwnerFor(const Caller& caller) { return {caller.principal, caller.connection}; }

// Whether `caller` may solve on, describe, attach to or close a session of `owner`: with
// authentication, its owner and admins; without, everyone (as before authentication).
bool MayUse(const Caller& caller, const SessionOwner& owner);
// Whether ListSessions shows it to `caller`: with authentication, what MayUse allows;
// without, the sessions the caller's own connection created, or all with `list_all`.
bool MayList(const Caller& caller, const SessionOwner& owner, bool list_all);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_AUTH_CALLER_H_
