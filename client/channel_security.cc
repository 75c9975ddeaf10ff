#include "client/channel_security.h"

#include <cstdlib>
#include <fstream>
#include <sstream>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"

namespace nupmpc {
namespace {

absl::StatusOr<std::string> ReadFile(const char* option, const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::InvalidArgumentError(absl::StrCat(option, " ", path, ": cannot be read"));
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// Adds `authorization: Bearer TOKEN` to every call of the channel.
class BearerTokenPlugin final : public grpc::MetadataCredentialsPlugin {
 public:
  explicit BearerTokenPlugin(const std::string& token) : header_(absl::StrCat("Bearer ", token)) {}
  bool IsBlocking() const override { return false; }
  grpc::Status GetMetadata(grpc::string_ref /*service_url*/, grpc::string_ref /*method_name*/,
                           const grpc::AuthContext& /*channel_auth_context*/,
                           std::multimap<grpc::string, grpc::string>* metadata) override {
    metadata->insert(std::make_pair("authorization", header_));
    return grpc::Status::OK;
  }

 private:
  const std::string header_;
};

bool IsLocalTarget(const std::string& target) {
  if (absl::StartsWith(target, "unix:") || absl::StartsWith(target, "unix-abstract:")) return true;
  for (const char* loopback : {"localhost:", "127.", "[::1]:", "ipv4:127.", "ipv6:[::1]:", "dns:///localhost:"}) {
    if (absl::StartsWith(target, loopback)) return true;
  }
  return false;
}

const char* Environment(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr && value[0] != '\0' ? value : nullptr;
}

}  // namespace

absl::StatusOr<std::string> ReadTokenFile(const std::string& path) {
  absl::StatusOr<std::string> text = ReadFile("token file", path);
  if (!text.ok()) return text.status();
  const std::string first_line = text->substr(0, text->find('\n'));
  const std::string token(absl::StripAsciiWhitespace(first_line));
  if (token.empty()) return absl::InvalidArgumentError(absl::StrCat("token file ", path, ": the first line is empty"));
  return token;
}

absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> ChannelCredentialsFor(const ChannelSecurity& security,
                                                                                const std::string& target) {
  std::shared_ptr<grpc::ChannelCredentials> channel;
  grpc_security_level token_needs = GRPC_PRIVACY_AND_INTEGRITY;
  if (security.uses_tls()) {
    grpc::SslCredentialsOptions ssl;
    if (!security.tls_ca_file.empty()) {
      absl::StatusOr<std::string> roots = ReadFile("tls_ca_file", security.tls_ca_file);
      if (!roots.ok()) return roots.status();
      ssl.pem_root_certs = *std::move(roots);
    }
    if (security.tls_cert_file.empty() != security.tls_key_file.empty()) {
      return absl::InvalidArgumentError("tls_cert_file and tls_key_file: give both or neither");
    }
    if (!security.tls_cert_file.empty()) {
      absl::StatusOr<std::string> chain = ReadFile("tls_cert_file", security.tls_cert_file);
      if (!chain.ok()) return chain.status();
      absl::StatusOr<std::string> key = ReadFile("tls_key_file", security.tls_key_file);
      if (!key.ok()) return key.status();
      ssl.pem_cert_chain = *std::move(chain);
      ssl.pem_private_key = *std::move(key);
    }
    channel = grpc::SslCredentials(ssl);
  } else if (!security.token.empty()) {
    if (!IsLocalTarget(target)) {
      return absl::InvalidArgumentError(
          absl::StrCat("token: sent only over TLS to a remote server (", target, "); give tls (or tls_ca_file)"));
    }
    const bool unix_socket = absl::StartsWith(target, "unix");
    channel = grpc::experimental::LocalCredentials(unix_socket ? UDS : LOCAL_TCP);
    // A loopback TCP connection is what gRPC calls security level NONE; nobody else sees it.
    if (!unix_socket) token_needs = GRPC_SECURITY_NONE;
  } else {
    return grpc::InsecureChannelCredentials();
  }
  if (security.token.empty()) return channel;
  return grpc::CompositeChannelCredentials(
      channel, grpc::experimental::MetadataCredentialsFromPlugin(std::make_unique<BearerTokenPlugin>(security.token),
                                                                 token_needs));
}

absl::StatusOr<ChannelSecurity> ChannelSecurityFromEnvironment() {
  ChannelSecurity security;
  if (const char* v = Environment("NUPMPC_TLS")) security.tls = std::string(v) == "1" || std::string(v) == "true";
  if (const char* v = Environment("NUPMPC_TLS_CA_FILE")) security.tls_ca_file = v;
  if (const char* v = Environment("NUPMPC_TLS_CERT_FILE")) security.tls_cert_file = v;
  if (const char* v = Environment("NUPMPC_TLS_KEY_FILE")) security.tls_key_file = v;
  if (const char* v = Environment("NUPMPC_TLS_SERVER_NAME")) security.tls_server_name = v;
  if (const char* v = Environment("NUPMPC_TOKEN")) security.token = v;
  if (const char* v = Environment("NUPMPC_TOKEN_FILE")) {
    absl::StatusOr<std::string> token = ReadTokenFile(v);
    if (!token.ok()) return token.status();
    security.token = *std::move(token);
  }
  return security;
}

}  // namespace nupmpc
