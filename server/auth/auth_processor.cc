#include "server/auth/auth_processor.h"

#include <string>

#include "absl/strings/match.h"
#include "absl/strings/string_view.h"
#include "grpc/grpc_security_constants.h"
#include "server/auth/caller.h"

namespace nupmpc::server {
namespace {

constexpr absl::string_view kBearerPrefix = "Bearer ";
constexpr absl::string_view kHealthService = "/grpc.health.v1.Health/";

absl::string_view View(const grpc::string_ref& s) { return absl::string_view(s.data(), s.size()); }

}  // namespace

grpc::Status AuthProcessor::Refuse(const char* why) {
  refused_.fetch_add(1, std::memory_order_relaxed);
  return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, why);
}

std::string AuthProcessor::PeerSubject(const grpc::AuthContext& context) {
  for (const grpc::string_ref& subject : context.FindPropertyValues(GRPC_X509_SUBJECT_PROPERTY_NAME)) {
    if (!subject.empty()) return std::string(subject.data(), subject.size());
  }
  return {};
}

grpc::Status AuthProcessor::Process(const InputMetadata& auth_metadata, grpc::AuthContext* context,
                                    OutputMetadata* consumed_auth_metadata, OutputMetadata* /*response_metadata*/) {
  // Load balancers and orchestrators probe health without credentials; it reveals only
  // SERVING or NOT_SERVING.
  if (const auto path = auth_metadata.find(":path");
      path != auth_metadata.end() && absl::StartsWith(View(path->second), kHealthService)) {
    return grpc::Status::OK;
  }
  const auto header = auth_metadata.find("authorization");
  if (const std::size_t given = auth_metadata.count("authorization"); given > 1) {
    // Which one would count is up to the order of headers: refuse rather than guess.
    return Refuse("authorization: given more than once; send one credential per call");
  }
  const std::string peer = PeerSubject(*context);
  const bool from_balancer = !trusted_balancer_subject_.empty() && peer == trusted_balancer_subject_;
  const auto forwarded = auth_metadata.find(kForwardedSubjectHeader);
  if (forwarded != auth_metadata.end()) {
    if (from_balancer && auth_metadata.count(kForwardedSubjectHeader) > 1) {
      return Refuse("x-nupmpc-client-subject: given more than once by the balancer");
    }
    // Consumed whoever sent it: handlers and logs never see a subject nobody vouched for.
    consumed_auth_metadata->insert(
        std::make_pair(std::string(kForwardedSubjectHeader), std::string(View(forwarded->second))));
  }
  if (header != auth_metadata.end()) {
    const absl::string_view value = View(header->second);
    if (tokens_ == nullptr) return Refuse("authorization: this server takes no bearer tokens (mTLS only)");
    if (!absl::StartsWith(value, kBearerPrefix)) return Refuse("authorization: expected \"Bearer TOKEN\"");
    const std::optional<Principal> principal = tokens_->Authenticate(value.substr(kBearerPrefix.size()));
    if (!principal.has_value()) return Refuse("authorization: the bearer token is not valid");
    context->AddProperty(kPrincipalProperty, principal->name);
    if (principal->admin) context->AddProperty(kAdminProperty, "1");
    context->AddProperty(kBearerTokenProperty, "1");
    // Consumed: the token does not reach the service's metadata (nor any log of it).
    consumed_auth_metadata->insert(
        std::make_pair(std::string(header->first.data(), header->first.size()), std::string(value)));
    return grpc::Status::OK;
  }
  if (from_balancer) {
    // The balancer's certificate proves only that the call came through the balancer.
    if (forwarded == auth_metadata.end() || forwarded->second.empty()) {
      return Refuse("a bearer token or a verified client certificate is required (the balancer forwarded neither)");
    }
    context->AddProperty(kPrincipalProperty, std::string(View(forwarded->second)));
    return grpc::Status::OK;
  }
  if (accept_client_certificates_ && !peer.empty()) {
    context->AddProperty(kPrincipalProperty, peer);
    return grpc::Status::OK;
  }
  return Refuse(tokens_ != nullptr ? "authorization: a bearer token is required (authorization: Bearer TOKEN)"
                                   : "a verified client certificate is required");
}

}  // namespace nupmpc::server
