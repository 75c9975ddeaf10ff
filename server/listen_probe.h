#ifndef NUPMPC_SERVER_LISTEN_PROBE_H_
#define NUPMPC_SERVER_LISTEN_PROBE_H_

// Before a listener starts: does its host resolve, and is any address it would bind taken
// by another process?
// gRPC (and the metrics port's HttpListener) start when at least one of an address's resolved addresses binds:
// `[::]:P` or `localhost:P` with one family's port held by another server would listen on
// the other family only, and clients reaching the first would talk to that other server,
// which does not know their sessions. So a server refuses to start instead.

#include <optional>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"

namespace nupmpc::server {

// Why a listener that passed CheckNotInUse can still fail to bind, for its message.
inline constexpr char kListenFailureCauses[] =
    "in use by another process, not this machine's address, or a port this user may not bind";

struct ListenHostPort {
  std::string host;  ///< a name or a numeric address, without brackets
  int port = 0;
};

// gRPC's TCP listening address, HOST:PORT or [V6]:PORT; nullopt for its other forms
// (unix:, unix-abstract:, vsock:, ...) and for what does not parse (gRPC reports those).
std::optional<ListenHostPort> SplitGrpcTcpAddress(absl::string_view address);

// How a listener binds an unspecified address (0.0.0.0 or ::).
enum class AnyAddress {
  kBothFamilies,  ///< gRPC: either one means every address of both families
  kAsGiven,       ///< HttpListener: the family written
};

// INVALID_ARGUMENT naming the host when it does not resolve; UNAVAILABLE naming the address
// in use when one of `host`'s addresses (resolved as the listener does) has `port` held by
// another socket; OK for port 0 and for addresses this
// machine cannot bind for other reasons (not its own, a family it lacks, a port it may not
// bind: the listener reports those). Each address is bound once, without listening, with
// SO_REUSEADDR as the listeners (a restart's connections in TIME_WAIT do not count), and
// closed again. `what` names the address in the message (the option and what was given).
absl::Status CheckNotInUse(const ListenHostPort& address, AnyAddress any, const std::string& what);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_LISTEN_PROBE_H_
