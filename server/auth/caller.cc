#include "server/auth/caller.h"

#include "grpcpp/security/auth_context.h"

namespace nupmpc::server {

Caller CallerOf(const grpc::ServerContextBase& context, const AuthProcessor* auth) {
  Caller caller;
  caller.connection = context.peer();
  if (auth == nullptr) return caller;
  const std::shared_ptr<const grpc::AuthContext> connection = context.auth_context();
  if (connection == nullptr) {
    caller.principal = kNobody;
    return caller;
  }
  const absl::StatusOr<AuthProcessor::Identity> identity = auth->Identify(context.client_metadata(), *connection);
  if (!identity.ok()) {
    caller.principal = kNobody;
    return caller;
  }
  caller.principal = identity->principal.name;
  caller.admin = identity->principal.admin;
  caller.by_token = identity->by_token;
  return caller;
}

bool MayUse(const Caller& caller, const SessionOwner& owner) {
  if (!caller.authenticated()) return true;
  return caller.admin || caller.principal == owner.principal;
}

bool MayList(const Caller& caller, const SessionOwner& owner, bool list_all) {
  if (caller.authenticated()) return MayUse(caller, owner);
  return list_all || caller.connection == owner.connection;
}

}  // namespace nupmpc::server
