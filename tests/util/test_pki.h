#ifndef NUPMPC_TESTS_UTIL_TEST_PKI_H_
#define NUPMPC_TESTS_UTIL_TEST_PKI_H_

// Certificates made at test time with Debian's openssl (never committed): two unrelated
// CAs, server certificates for localhost / 127.0.0.1 and client certificates.

#include <string>

#include "absl/status/statusor.h"

namespace nupmpc::testing {

struct KeyPair {
  std::string cert_file;  ///< PEM certificate
  std::string key_file;   ///< PEM private key
};

class TestPki {
 public:
  // A new directory under `parent` with the two CAs ("ca", "other_ca").
  static absl::StatusOr<TestPki> Create(const std::string& parent);

  // A certificate for `subject` (e.g. "/CN=alice/O=plant") signed by `ca` ("ca" or
  // "other_ca"); `server`: with the names localhost and 127.0.0.1.
  absl::StatusOr<KeyPair> Issue(const std::string& name, const std::string& subject, const std::string& ca,
                                bool server) const;
  // The subject of the certificate in `cert_file` as RFC 2253 prints it (openssl's
  // -nameopt RFC2253): how gRPC names an mTLS peer and HAProxy's ssl_c_s_dn(,,rfc2253).
  static absl::StatusOr<std::string> SubjectOf(const std::string& cert_file);
  std::string CaFile(const std::string& ca) const { return dir_ + "/" + ca + ".pem"; }
  const std::string& dir() const { return dir_; }

 private:
  explicit TestPki(std::string dir) : dir_(std::move(dir)) {}
  std::string dir_;
};

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_TEST_PKI_H_
