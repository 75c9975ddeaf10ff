#ifndef NUPMPC_LOADTEST_TRANSPORT_FLOOR_H_
#define NUPMPC_LOADTEST_TRANSPORT_FLOOR_H_

// The second peer of the load test, measured in the same run: gRPC's own round trip on this
// machine. grpc.health.v1.Health/Check is answered inside gRPC (no nupmpc code runs), so
// its latency is what the transport alone costs; a Control step cannot come back faster
// than the core's solve plus about this much.

#include <string>

#include "absl/status/statusor.h"
#include "client/channel_security.h"

namespace nupmpc::loadtest {

struct TransportFloor {
  double p50_us = 0.0;
  double p99_us = 0.0;
  int calls = 0;
};

// `calls` sequential health checks on a channel of their own (after a few warm-up calls).
absl::StatusOr<TransportFloor> MeasureTransportFloor(const std::string& target, int calls,
                                                     const ChannelSecurity& security = {});

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_TRANSPORT_FLOOR_H_
