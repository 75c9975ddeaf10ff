#ifndef NUPMPC_SERVER_METRICS_EXPOSITION_H_
#define NUPMPC_SERVER_METRICS_EXPOSITION_H_

// The server's state as Prometheus metrics (GET /metrics, server/metrics_http.h): the
// counters and histograms of server/observability/metrics.h (the ones GetServerInfo reports), the
// session registry's counts, the worker pool, memory and process gauges, build info.
// Labels have bounded values (statuses, algorithms, RPC names, status codes): never a
// session id.

#include <string>

#include "server/state/server_state.h"

namespace nupmpc::server {

std::string RenderPrometheusMetrics(const ServerState& state);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_METRICS_EXPOSITION_H_
