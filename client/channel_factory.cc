#include "client/channel_factory.h"

namespace nupmpc {
namespace {

grpc::ChannelArguments ArgumentsFor(const ChannelOptions& options) {
  grpc::ChannelArguments args = options.extra;
  if (options.own_connection) args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  if (options.unlimited_receive) args.SetMaxReceiveMessageSize(-1);
  if (options.unlimited_send) args.SetMaxSendMessageSize(-1);
  if (options.keepalive) {
    args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, 2000);
    args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 2000);
    args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
    args.SetInt(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  }
  return args;
}

}  // namespace

ChannelOptions ClientChannelOptions(bool own_connection) {
  ChannelOptions options;
  options.own_connection = own_connection;
  options.unlimited_receive = true;
  options.unlimited_send = true;
  options.keepalive = true;
  return options;
}

std::shared_ptr<grpc::Channel> OpenChannel(const std::string& target, const ChannelOptions& options) {
  return grpc::CreateCustomChannel(target, grpc::InsecureChannelCredentials(), ArgumentsFor(options));
}

std::shared_ptr<grpc::Channel> OpenChannel(const std::string& target,
                                           const std::shared_ptr<grpc::ChannelCredentials>& credentials,
                                           const ChannelSecurity& security, const ChannelOptions& options) {
  grpc::ChannelArguments args = ArgumentsFor(options);
  if (security.uses_tls() && !security.tls_server_name.empty()) args.SetSslTargetNameOverride(security.tls_server_name);
  return grpc::CreateCustomChannel(target, credentials, args);
}

absl::StatusOr<std::shared_ptr<grpc::Channel>> OpenChannel(const std::string& target, const ChannelSecurity& security,
                                                           const ChannelOptions& options) {
  absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> credentials = ChannelCredentialsFor(security, target);
  if (!credentials.ok()) return credentials.status();
  return OpenChannel(target, *credentials, security, options);
}

}  // namespace nupmpc
