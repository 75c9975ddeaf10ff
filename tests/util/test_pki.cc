#include "tests/util/test_pki.h"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"

namespace nupmpc::testing {
namespace {

absl::Status Run(const std::string& command) {
  const std::string quiet = absl::StrCat(command, " >/dev/null 2>&1");
  if (std::system(quiet.c_str()) != 0) return absl::InternalError(absl::StrCat("failed: ", command));
  return absl::OkStatus();
}

// P-256 keys: fast to make, and what a deployment would choose today.
constexpr char kNewKey[] = "openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes";

}  // namespace

absl::StatusOr<TestPki> TestPki::Create(const std::string& parent) {
  const std::string dir = absl::StrCat(parent, "/pki-", getpid(), "-", std::rand());
  std::error_code error;
  std::filesystem::create_directories(dir, error);
  if (error) return absl::InternalError(absl::StrCat(dir, ": ", error.message()));
  for (const char* ca : {"ca", "other_ca"}) {
    const absl::Status made = Run(absl::StrCat(kNewKey, " -x509 -days 2 -keyout ", dir, "/", ca, ".key -out ", dir, "/",
                                               ca, ".pem -subj /CN=nupmpc-test-", ca));
    if (!made.ok()) return made;
  }
  return TestPki(dir);
}

absl::StatusOr<KeyPair> TestPki::Issue(const std::string& name, const std::string& subject, const std::string& ca,
                                       bool server) const {
  const std::string base = absl::StrCat(dir_, "/", name);
  const std::string extensions = base + ".ext";
  {
    std::ofstream ext(extensions);
    ext << (server ? "subjectAltName=DNS:localhost,IP:127.0.0.1\nextendedKeyUsage=serverAuth\n"
                   : "extendedKeyUsage=clientAuth\n");
  }
  if (absl::Status s = Run(absl::StrCat(kNewKey, " -keyout ", base, ".key -out ", base, ".csr -subj ", subject));
      !s.ok()) {
    return s;
  }
  if (absl::Status s =
          Run(absl::StrCat("openssl x509 -req -days 2 -in ", base, ".csr -CA ", CaFile(ca), " -CAkey ", dir_, "/", ca,
                           ".key -CAcreateserial -out ", base, ".pem -extfile ", extensions));
      !s.ok()) {
    return s;
  }
  return KeyPair{base + ".pem", base + ".key"};
}

absl::StatusOr<std::string> TestPki::SubjectOf(const std::string& cert_file) {
  const std::string command = absl::StrCat("openssl x509 -noout -subject -nameopt RFC2253 -in ", cert_file);
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return absl::InternalError(absl::StrCat("failed: ", command));
  std::string out;
  char buffer[512];
  while (std::fgets(buffer, sizeof buffer, pipe) != nullptr) out += buffer;
  if (pclose(pipe) != 0) return absl::InternalError(absl::StrCat("failed: ", command));
  constexpr absl::string_view kPrefix = "subject=";
  absl::string_view subject = absl::StripAsciiWhitespace(out);
  if (!absl::ConsumePrefix(&subject, kPrefix)) return absl::InternalError(absl::StrCat(command, ": ", out));
  return std::string(absl::StripLeadingAsciiWhitespace(subject));
}

}  // namespace nupmpc::testing
