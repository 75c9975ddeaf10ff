#ifndef NUPMPC_SERVER_AUTH_TRANSPORT_SECURITY_H_
#define NUPMPC_SERVER_AUTH_TRANSPORT_SECURITY_H_

// How the server's port is secured: TLS from PEM files that gRPC's file-watcher provider
// re-reads (certificate rotation without a restart), mTLS when a client CA is given, and
// bearer-token authentication in an AuthMetadataProcessor (server/auth/auth_processor.h).

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "grpcpp/security/server_credentials.h"
#include "server/auth/auth_processor.h"

namespace nupmpc::server {

struct TlsFiles {
  std::string cert_file;       ///< PEM certificate chain; empty: no TLS
  std::string key_file;        ///< its PEM private key
  std::string client_ca_file;  ///< PEM CA bundle: client certificates required and verified (mTLS)
  int reload_interval_s = 10;  ///< how often the files are checked for changes
  /// The subject (RFC 2253) of the balancer's client certificate: that peer may name the
  /// caller in a header (server/auth/auth_processor.h); empty: no peer may.
  std::string trusted_balancer_subject;

  bool enabled() const { return !cert_file.empty(); }
  bool mutual() const { return !client_ca_file.empty(); }
};

// The files given make sense together (certificate and key both or neither, a client CA
// only with them, every file readable PEM); errors name the flag.
absl::Status CheckTlsFiles(const TlsFiles& tls);

// Whether `address` (host:port, unix:path) accepts only connections from this machine.
bool IsLocalAddress(absl::string_view address);

// The credentials of the listening port. With TLS: TLS (mTLS with a client CA). Without
// TLS and without authentication: insecure. Without TLS but with authentication (tokens
// on a loopback address only): gRPC's local credentials, which accept only connections
// from this machine and, unlike insecure ones, run an AuthMetadataProcessor.
// `auth`: the processor, or null when authentication is off.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(const TlsFiles& tls,
                                                                              absl::string_view address,
                                                                              std::shared_ptr<AuthProcessor> auth);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_AUTH_TRANSPORT_SECURITY_H_
