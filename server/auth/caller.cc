#include "server/auth/caller.h"

#include "grpcpp/security/auth_context.h"

namespace nupmpc::server {

Caller CallerOf(const grpc::ServerContextBase& context) {
  Caller caller;
  caller.connection = context.peer();
  const std::shared_ptr<const grpc::AuthContext> auth = context.auth_context();
  if (auth == nullptr) return caller;
  for (const grpc::string_ref& value : auth->FindPropertyValues(kPrincipalProperty)) {
    caller.principal.assign(value.data(), value.size());
  }
  caller.admin = !auth->FindPropertyValues(kAdminProperty).empty();
  caller.by_token = !auth->FindPropertyValues(kBearerTokenProperty).empty();
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
