#include "server/auth/auth_processor.h"

#include <optional>
#include <string>

#include "absl/strings/match.h"
#include "absl/strings/string_view.h"
#include "grpc/grpc_security_constants.h"

namespace nupmpc::server {
namespace {

constexpr absl::string_view kBearerPrefix = "Bearer ";
constexpr absl::string_view kHealthService = "/grpc.health.v1.Health/";

absl::string_view View(const grpc::string_ref& s) { return absl::string_view(s.data(), s.size()); }

}  // namespace

grpc::Status AuthProcessor::Refuse(absl::string_view why) {
  refused_.fetch_add(1, std::memory_order_relaxed);
  return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, std::string(why));
}

std::string AuthProcessor::PeerSubject(const grpc::AuthContext& context) {
  for (const grpc::string_ref& subject : context.FindPropertyValues(GRPC_X509_SUBJECT_PROPERTY_NAME)) {
    if (!subject.empty()) return std::string(subject.data(), subject.size());
  }
  return {};
}

grpc::Status AuthProcessor::Process(const InputMetadata& auth_metadata, grpc::AuthContext* context,
                                    OutputMetadata* /*consumed_auth_metadata*/, OutputMetadata* /*response_metadata*/) {
  // Load balancers and orchestrators probe health without credentials; it reveals only
  // SERVING or NOT_SERVING.
  if (const auto path = auth_metadata.find(":path");
      path != auth_metadata.end() && absl::StartsWith(View(path->second), kHealthService)) {
    return grpc::Status::OK;
  }
  // Nothing is consumed: the service identifies the call again from the same headers
  // (CallerOf); no handler logs them.
  const absl::StatusOr<Identity> identity = Identify(auth_metadata, *context);
  if (!identity.ok()) return Refuse(identity.status().message());
  return grpc::Status::OK;
}

absl::StatusOr<AuthProcessor::Identity> AuthProcessor::Identify(const InputMetadata& metadata,
                                                                const grpc::AuthContext& connection) const {
  const auto header = metadata.find("authorization");
  if (metadata.count("authorization") > 1) {
    // Which one would count is up to the order of headers: refuse rather than guess.
    return absl::UnauthenticatedError("authorization: given more than once; send one credential per call");
  }
  const std::string peer = PeerSubject(connection);
  const bool from_balancer = !trusted_balancer_subject_.empty() && peer == trusted_balancer_subject_;
  const auto forwarded = metadata.find(kForwardedSubjectHeader);
  if (from_balancer && metadata.count(kForwardedSubjectHeader) > 1) {
    return absl::UnauthenticatedError("x-nupmpc-client-subject: given more than once by the balancer");
  }
  if (header != metadata.end()) {
    const absl::string_view value = View(header->second);
    if (tokens_ == nullptr) {
      return absl::UnauthenticatedError("authorization: this server takes no bearer tokens (mTLS only)");
    }
    if (!absl::StartsWith(value, kBearerPrefix)) {
      return absl::UnauthenticatedError("authorization: expected \"Bearer TOKEN\"");
    }
    std::optional<Principal> principal = tokens_->Authenticate(value.substr(kBearerPrefix.size()));
    if (!principal.has_value()) return absl::UnauthenticatedError("authorization: the bearer token is not valid");
    return Identity{*std::move(principal), /*by_token=*/true};
  }
  if (from_balancer) {
    // The balancer's certificate proves only that the call came through the balancer.
    if (forwarded == metadata.end() || forwarded->second.empty()) {
      return absl::UnauthenticatedError(
          "a bearer token or a verified client certificate is required (the balancer forwarded neither)");
    }
    return Identity{{std::string(View(forwarded->second)), false}, false};
  }
  if (accept_client_certificates_ && !peer.empty()) return Identity{{peer, false}, false};
  return absl::UnauthenticatedError(tokens_ != nullptr
                                        ? "authorization: a bearer token is required (authorization: Bearer TOKEN)"
                                        : "a verified client certificate is required");
}

}  // namespace nupmpc::server
