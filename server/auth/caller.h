#ifndef NUPMPC_SERVER_AUTH_CALLER_H_
#define NUPMPC_SERVER_AUTH_CALLER_H_

// Who made a call, and what that caller may do with a session: sessions belong to the
// principal that created them (server/auth/auth_processor.h sets it on the call).

#include <string>

#include "grpcpp/server_context.h"

namespace nupmpc::server {

// Properties the authentication processor adds to a call's AuthContext.
inline constexpr char kPrincipalProperty[] = "nupmpc_principal";
inline constexpr char kAdminProperty[] = "nupmpc_admin";
inline constexpr char kBearerTokenProperty[] = "nupmpc_bearer_token";  ///< set when a token authenticated the call

struct Caller {
  std::string principal;   ///< empty: authentication is off
  bool admin = false;      ///< may see and close every session
  bool by_token = false;   ///< authenticated by a bearer token (revoked with it), not a certificate
  std::string connection;  ///< the peer address (one per client connection)

  bool authenticated() const { return !principal.empty(); }
};

Caller CallerOf(const grpc::ServerContextBase& context);

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
