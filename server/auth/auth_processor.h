#ifndef NUPMPC_SERVER_AUTH_AUTH_PROCESSOR_H_
#define NUPMPC_SERVER_AUTH_AUTH_PROCESSOR_H_

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "grpcpp/security/auth_metadata_processor.h"
#include "server/auth/token_file.h"

namespace nupmpc::server {

// The header in which a trusted balancer names the caller whose client certificate it
// verified: the certificate's subject, RFC 2253 (HAProxy's ssl_c_s_dn(,,rfc2253)), which
// is how gRPC names a direct mTLS caller too, so both reach the same principal.
inline constexpr char kForwardedSubjectHeader[] = "x-nupmpc-client-subject";

// Authenticates every call before it reaches the service: an `authorization: Bearer TOKEN`
// header must name a token of `tokens`; a call without one is accepted when its TLS client
// certificate was verified (mTLS), its subject being the principal. Anything else is
// UNAUTHENTICATED, except grpc.health.v1 (probes carry no credentials). Tokens are never
// logged or echoed.
//
// gRPC gives every call of a connection the connection's one AuthContext, so nothing about
// a call may be stored there: behind a balancer one connection carries many callers' calls.
// Process only refuses; the service asks Identify again for each call, from that call's own
// metadata (server/auth/caller.h), under the same rules.
//
// Behind a balancer that terminates the clients' TLS, the replica's peer is the balancer.
// When the peer's verified certificate subject equals `trusted_balancer_subject`, a call
// without a token is the caller named in kForwardedSubjectHeader, and without that header
// UNAUTHENTICATED: the balancer's own certificate is never a principal. From any other
// peer the header is ignored (a caller reaching a replica directly is only what its own
// token or certificate makes it).
class AuthProcessor final : public grpc::AuthMetadataProcessor {
 public:
  // `tokens` may be null (certificates only); `accept_client_certificates`: mTLS is on;
  // `trusted_balancer_subject`: empty, no peer is trusted to forward callers.
  AuthProcessor(std::shared_ptr<const TokenStore> tokens, bool accept_client_certificates,
                std::string trusted_balancer_subject = {})
      : tokens_(std::move(tokens)),
        accept_client_certificates_(accept_client_certificates),
        trusted_balancer_subject_(std::move(trusted_balancer_subject)) {}

  // A table lookup: answered on gRPC's own thread.
  bool IsBlocking() const override { return false; }
  grpc::Status Process(const InputMetadata& auth_metadata, grpc::AuthContext* context,
                       OutputMetadata* consumed_auth_metadata, OutputMetadata* response_metadata) override;

  struct Identity {
    Principal principal;
    bool by_token = false;  ///< a bearer token, revoked with it; else a certificate
  };
  // The caller of a call with `metadata` on a connection with `connection`'s certificate;
  // UNAUTHENTICATED with the reason when there is none.
  absl::StatusOr<Identity> Identify(const InputMetadata& metadata, const grpc::AuthContext& connection) const;

  std::uint64_t refused_total() const { return refused_.load(std::memory_order_relaxed); }

 private:
  grpc::Status Refuse(absl::string_view why);
  // The verified client certificate's subject of the call's connection; empty: none.
  static std::string PeerSubject(const grpc::AuthContext& context);

  const std::shared_ptr<const TokenStore> tokens_;
  const bool accept_client_certificates_;
  const std::string trusted_balancer_subject_;
  std::atomic<std::uint64_t> refused_{0};
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_AUTH_AUTH_PROCESSOR_H_
