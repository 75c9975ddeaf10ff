#ifndef NUPMPC_SERVER_METRICS_HTTP_H_
#define NUPMPC_SERVER_METRICS_HTTP_H_

// The operators' HTTP endpoint (--metrics_address): GET /metrics in the Prometheus text
// format, /healthz (200 while the process runs) and /readyz (200 while the gRPC health
// service says SERVING, 503 from SIGTERM on), served by an HttpListener on a thread of its
// own, so a scrape never waits for a solver worker and a slow or hostile peer of this
// unauthenticated port cannot hold it (the listener's bounds are in http_listener.h).

#include <functional>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "server/http/http_listener.h"
#include "server/listen_probe.h"

namespace nupmpc::server {

// `address` (HOST:PORT, [V6]:PORT or :PORT) as the endpoint binds it: :PORT is IPv4's every
// address, 0.0.0.0. INVALID_ARGUMENT naming --metrics_address when it does not parse.
absl::StatusOr<ListenHostPort> ParseMetricsAddress(const std::string& address);

class MetricsHttpServer {
 public:
  // `address` is HOST:PORT or :PORT (all interfaces); port 0 picks a free one.
  static absl::StatusOr<std::unique_ptr<MetricsHttpServer>> Start(const std::string& address,
                                                                  std::function<std::string()> render_metrics,
                                                                  std::function<bool()> ready);
  int port() const { return listener_->port(); }
  HttpListenerCounts counts() const { return listener_->counts(); }

 private:
  explicit MetricsHttpServer(std::unique_ptr<HttpListener> listener) : listener_(std::move(listener)) {}
  std::unique_ptr<HttpListener> listener_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_METRICS_HTTP_H_
