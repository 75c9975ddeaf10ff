#ifndef NUPMPC_SERVER_AUTH_AUTH_PROCESSOR_H_
#define NUPMPC_SERVER_AUTH_AUTH_PROCESSOR_H_

#include <atomic>
#include <cstdint>
#include <memory>

#include "grpcpp/security/auth_metadata_processor.h"
#include "server/auth/token_file.h"

namespace nupmpc::server {

// Authenticates every call before it reaches the service: an `authorization: Bearer TOKEN`
// header must name a token of `tokens`; a call without one is accepted when its TLS client
// certificate was verified (mTLS), its subject being the principal. Anything else is
// UNAUTHENTICATED, except grpc.health.v1 (probes carry no credentials). The principal (and admin role) is added to the
// call's AuthContext (server/auth/caller.h reads it). Tokens are never logged or echoed.
class AuthProcessor final : public grpc::AuthMetadataProcessor {
 public:
  // `tokens` may be null (certificates only); `accept_client_certificates`: mTLS is on.
  AuthProcessor(std::shared_ptr<const TokenStore> tokens, bool accept_client_certificates)
      : tokens_(std::move(tokens)), accept_client_certificates_(accept_client_certificates) {}

  // A table lookup: answered on gRPC's own thread.
  bool IsBlocking() const override { return false; }
  grpc::Status Process(const InputMetadata& auth_metadata, grpc::AuthContext* context,
                       OutputMetadata* consumed_auth_metadata, OutputMetadata* response_metadata) override;

  std::uint64_t refused_total() const { return refused_.load(std::memory_order_relaxed); }

 private:
  grpc::Status Refuse(const char* why);

  const std::shared_ptr<const TokenStore> tokens_;
  const bool accept_client_certificates_;
  std::atomic<std::uint64_t> refused_{0};
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_AUTH_AUTH_PROCESSOR_H_
