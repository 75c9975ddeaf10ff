#include "server/auth/transport_security.h"

#include <fstream>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "grpcpp/security/tls_certificate_provider.h"
#include "grpcpp/security/tls_credentials_options.h"

namespace nupmpc::server {
namespace {

absl::Status CheckPemFile(const char* flag, const std::string& path, absl::string_view expected) {
  std::ifstream in(path);
  if (!in) return absl::InvalidArgumentError(absl::StrCat("--", flag, " ", path, ": cannot be read"));
  std::stringstream text;
  text << in.rdbuf();
  if (!absl::StrContains(text.str(), "-----BEGIN ") || !absl::StrContains(text.str(), expected)) {
    return absl::InvalidArgumentError(absl::StrCat("--", flag, " ", path, ": not a PEM file with a ", expected));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status CheckTlsFiles(const TlsFiles& tls) {
  if (tls.cert_file.empty() != tls.key_file.empty()) {
    return absl::InvalidArgumentError("--tls_cert_file and --tls_key_file: give both or neither");
  }
  if (!tls.trusted_balancer_subject.empty()) {
    if (!tls.mutual()) {
      return absl::InvalidArgumentError(
          "--trusted_balancer_subject: needs --tls_client_ca_file (the balancer is known by its client certificate)");
    }
    const absl::string_view subject = tls.trusted_balancer_subject;
    if (!absl::StrContains(subject, '=') || absl::StripAsciiWhitespace(subject) != subject) {
      return absl::InvalidArgumentError(
          absl::StrCat("--trusted_balancer_subject = \"", subject,
                       "\": expected a certificate subject as RFC 2253 prints it, e.g. CN=nupmpc-balancer,O=example "
                       "(openssl x509 -noout -subject -nameopt RFC2253)"));
    }
  }
  if (!tls.enabled()) {
    if (tls.mutual())
      return absl::InvalidArgumentError("--tls_client_ca_file: needs --tls_cert_file and --tls_key_file");
    return absl::OkStatus();
  }
  if (absl::Status s = CheckPemFile("tls_cert_file", tls.cert_file, "CERTIFICATE"); !s.ok()) return s;
  if (absl::Status s = CheckPemFile("tls_key_file", tls.key_file, "PRIVATE KEY"); !s.ok()) return s;
  if (tls.mutual()) {
    if (absl::Status s = CheckPemFile("tls_client_ca_file", tls.client_ca_file, "CERTIFICATE"); !s.ok()) return s;
  }
  if (tls.reload_interval_s < 1) return absl::InvalidArgumentError("--tls_reload_interval_s: must be >= 1");
  return absl::OkStatus();
}

bool IsLocalAddress(absl::string_view address) {
  if (absl::StartsWith(address, "unix:") || absl::StartsWith(address, "unix-abstract:")) return true;
  for (absl::string_view loopback : {"localhost:", "127.", "[::1]:", "ipv4:127.", "ipv6:[::1]:"}) {
    if (absl::StartsWith(address, loopback)) return true;
  }
  return false;
}

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(const TlsFiles& tls,
                                                                              absl::string_view address,
                                                                              std::shared_ptr<AuthProcessor> auth) {
  if (absl::Status s = CheckTlsFiles(tls); !s.ok()) return s;
  std::shared_ptr<grpc::ServerCredentials> credentials;
  if (tls.enabled()) {
    auto provider = std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
        tls.key_file, tls.cert_file, tls.client_ca_file, static_cast<unsigned>(tls.reload_interval_s));
    grpc::experimental::TlsServerCredentialsOptions options(provider);
    options.watch_identity_key_cert_pairs();
    if (tls.mutual()) {
      options.watch_root_certs();
      options.set_cert_request_type(GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
    } else {
      options.set_cert_request_type(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
    }
    credentials = grpc::experimental::TlsServerCredentials(options);
  } else if (auth != nullptr) {
    // Bearer tokens in clear text only where nobody else can read them.
    if (!IsLocalAddress(address)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--auth_tokens_file: bearer tokens need TLS (--tls_cert_file, --tls_key_file) on a non-loopback address (",
          address, ")"));
    }
    credentials = grpc::experimental::LocalServerCredentials(absl::StartsWith(address, "unix") ? UDS : LOCAL_TCP);
  } else {
    return grpc::InsecureServerCredentials();
  }
  if (auth != nullptr) credentials->SetAuthMetadataProcessor(std::move(auth));
  return credentials;
}

}  // namespace nupmpc::server
