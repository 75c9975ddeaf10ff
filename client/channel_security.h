#ifndef NUPMPC_CLIENT_CHANNEL_SECURITY_H_
#define NUPMPC_CLIENT_CHANNEL_SECURITY_H_

// How a client reaches a server that uses TLS, mTLS or bearer tokens (the server's
// --tls_* and --auth_tokens_file flags).

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "grpcpp/grpcpp.h"

namespace nupmpc {

struct ChannelSecurity {
  bool tls = false;             ///< TLS, verified against the system's CAs unless tls_ca_file
  std::string tls_ca_file;      ///< PEM CAs that signed the server's certificate (implies tls)
  std::string tls_cert_file;    ///< client certificate for mTLS (implies tls; with tls_key_file)
  std::string tls_key_file;     ///< its private key
  std::string tls_server_name;  ///< the name the server's certificate must carry, when not the target's host
  std::string token;            ///< sent as `authorization: Bearer TOKEN` on every call

  bool uses_tls() const { return tls || !tls_ca_file.empty() || !tls_cert_file.empty(); }
};

// Credentials for a channel to `target`: TLS when asked for, else plaintext; a token rides
// on every call. Without TLS a token is sent only to a loopback or Unix-socket target (gRPC's
// local credentials): it would cross the network in clear text otherwise. Errors name the
// option (unreadable files, a token without TLS to a remote target).
absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> ChannelCredentialsFor(const ChannelSecurity& security,
                                                                                const std::string& target);

// ChannelSecurity from the environment, for command-line tools and tests: NUPMPC_TLS (1:
// on), NUPMPC_TLS_CA_FILE, NUPMPC_TLS_CERT_FILE, NUPMPC_TLS_KEY_FILE,
// NUPMPC_TLS_SERVER_NAME, NUPMPC_TOKEN or NUPMPC_TOKEN_FILE (first line).
absl::StatusOr<ChannelSecurity> ChannelSecurityFromEnvironment();

// A token file's token: its first line, surrounding white space removed.
absl::StatusOr<std::string> ReadTokenFile(const std::string& path);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_CHANNEL_SECURITY_H_
