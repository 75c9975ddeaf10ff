#ifndef NUPMPC_CLIENT_CHANNEL_FACTORY_H_
#define NUPMPC_CLIENT_CHANNEL_FACTORY_H_

// How a gRPC channel to a server is made: the one place where the client library, the load
// test, the soak helpers and the tests choose its arguments. Each option is off by default,
// so that OpenChannel(target) is gRPC's plain channel.

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "client/channel_security.h"
#include "grpcpp/grpcpp.h"

namespace nupmpc {

struct ChannelOptions {
  // A TCP connection of this channel's own, not shared through gRPC's global subchannel
  // pool with other channels to the same address (nor their reconnect back-off): what
  // separate plant computers would have.
  bool own_connection = false;
  // Messages of any size (gRPC refuses to receive more than 4 MB by default; plans of long
  // horizons exceed it, and the server enforces a limit of its own).
  bool unlimited_receive = false;
  bool unlimited_send = false;
  // HTTP/2 keepalive: a ping every 2 s, also without calls in flight, and the connection
  // closed when one is not answered within 2 s, so a partition or a frozen server is found
  // in seconds rather than by TCP's timers (minutes). nupmpc-server accepts pings this often;
  // the Python client sends the same (client/python/nupmpc/security.py).
  bool keepalive = false;
  // Anything else, set on top (a test's transport settings).
  grpc::ChannelArguments extra;
};

// The client library's own channels (Client): messages of any size, keepalive.
ChannelOptions ClientChannelOptions(bool own_connection);

// A plaintext channel to `target`.
std::shared_ptr<grpc::Channel> OpenChannel(const std::string& target, const ChannelOptions& options = {});
// A channel with `credentials` (from ChannelCredentialsFor(security, target)), plus the
// arguments the security needs (the TLS server name override).
std::shared_ptr<grpc::Channel> OpenChannel(const std::string& target,
                                           const std::shared_ptr<grpc::ChannelCredentials>& credentials,
                                           const ChannelSecurity& security, const ChannelOptions& options);
// The same with credentials made here (errors as ChannelCredentialsFor's).
absl::StatusOr<std::shared_ptr<grpc::Channel>> OpenChannel(const std::string& target, const ChannelSecurity& security,
                                                           const ChannelOptions& options);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_CHANNEL_FACTORY_H_
