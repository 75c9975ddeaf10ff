#include "client/security_flags.h"

#include <string>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"

ABSL_FLAG(bool, tls, false, "connect with TLS, verifying the server against the system's CAs (env NUPMPC_TLS=1)");
ABSL_FLAG(std::string, tls_ca_file, "",
          "PEM CAs that signed the server's certificate; implies --tls (env NUPMPC_TLS_CA_FILE)");
ABSL_FLAG(std::string, tls_cert_file, "", "client certificate for mTLS; implies --tls (env NUPMPC_TLS_CERT_FILE)");
ABSL_FLAG(std::string, tls_key_file, "", "private key of --tls_cert_file (env NUPMPC_TLS_KEY_FILE)");
ABSL_FLAG(
    std::string, tls_server_name, "",
    "the name the server's certificate must carry, when not the host of the address (env NUPMPC_TLS_SERVER_NAME)");
ABSL_FLAG(std::string, token_file, "",
          "file whose first line is the bearer token sent on every call (env NUPMPC_TOKEN_FILE, or the token itself "
          "in NUPMPC_TOKEN)");

namespace nupmpc {

absl::StatusOr<ChannelSecurity> ChannelSecurityFromFlags() {
  absl::StatusOr<ChannelSecurity> security = ChannelSecurityFromEnvironment();
  if (!security.ok()) return security.status();
  if (absl::GetFlag(FLAGS_tls)) security->tls = true;
  for (auto [flag, field] : {std::make_pair(&FLAGS_tls_ca_file, &security->tls_ca_file),
                             std::make_pair(&FLAGS_tls_cert_file, &security->tls_cert_file),
                             std::make_pair(&FLAGS_tls_key_file, &security->tls_key_file),
                             std::make_pair(&FLAGS_tls_server_name, &security->tls_server_name)}) {
    if (std::string value = absl::GetFlag(*flag); !value.empty()) *field = std::move(value);
  }
  if (const std::string path = absl::GetFlag(FLAGS_token_file); !path.empty()) {
    absl::StatusOr<std::string> token = ReadTokenFile(path);
    if (!token.ok()) return absl::InvalidArgumentError(absl::StrCat("--token_file: ", token.status().message()));
    security->token = *std::move(token);
  }
  return security;
}

std::vector<std::string> SecurityFlagArguments() {
  std::vector<std::string> out;
  if (absl::GetFlag(FLAGS_tls)) out.push_back("--tls");
  for (const auto& [name, flag] :
       {std::make_pair("tls_ca_file", &FLAGS_tls_ca_file), std::make_pair("tls_cert_file", &FLAGS_tls_cert_file),
        std::make_pair("tls_key_file", &FLAGS_tls_key_file), std::make_pair("tls_server_name", &FLAGS_tls_server_name),
        std::make_pair("token_file", &FLAGS_token_file)}) {
    if (const std::string value = absl::GetFlag(*flag); !value.empty())
      out.push_back(absl::StrCat("--", name, "=", value));
  }
  return out;
}

}  // namespace nupmpc
