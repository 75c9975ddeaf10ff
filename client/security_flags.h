#ifndef NUPMPC_CLIENT_SECURITY_FLAGS_H_
#define NUPMPC_CLIENT_SECURITY_FLAGS_H_

// The connection-security flags the command-line tools share: --tls, --tls_ca_file,
// --tls_cert_file, --tls_key_file, --tls_server_name, --token_file (a token is never taken
// on the command line, where `ps` shows it).

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/channel_security.h"

namespace nupmpc {

// The flags, each falling back to its environment variable (ChannelSecurityFromEnvironment)
// when not given.
absl::StatusOr<ChannelSecurity> ChannelSecurityFromFlags();

// The security flags given to this process, as arguments for a child process of the same
// program (e.g. "--tls_ca_file=ca.pem").
std::vector<std::string> SecurityFlagArguments();

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_SECURITY_FLAGS_H_
