#ifndef NUPMPC_SERVER_LISTEN_PROBE_H_
#define NUPMPC_SERVER_LISTEN_PROBE_H_

// Before a listener starts: is any address it would bind taken by another process?
// gRPC (and cpp-httplib) start when at least one of an address's resolved addresses binds:
// `localhost:P` or `[::]:P` with one family's port held by another server would listen on
// the other family only, and clients reaching the first would talk to that other server,
// which does not know their sessions. So a server refuses to start instead.

#include <string>

#include "absl/status/status.h"

namespace nupmpc::server {

// UNAVAILABLE naming the address in use when a TCP address of `address` (gRPC's forms:
// HOST:PORT, [V6]:PORT, :PORT, ipv4:/ipv6: prefixes) is held by another socket; OK for
// port 0, Unix socket addresses, and addresses this machine cannot bind for other reasons
// (not its own, a family it lacks, a port it may not bind: the listener reports those).
// Each resolved address is bound once, without listening, and closed again.
// `what` names the address in the message (the option and what was given).
absl::Status CheckNotInUse(const std::string& address, const std::string& what);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_LISTEN_PROBE_H_
