#include "server/metrics_http.h"

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"

namespace nupmpc::server {

absl::StatusOr<ListenHostPort> ParseMetricsAddress(const std::string& address) {
  const std::size_t colon = address.rfind(':');
  int port = -1;
  if (colon == std::string::npos || !absl::SimpleAtoi(address.substr(colon + 1), &port) || port < 0 || port > 65535) {
    return absl::InvalidArgumentError(
        absl::StrCat("--metrics_address \"", address, "\": expected HOST:PORT or :PORT (e.g. :9464)"));
  }
  std::string host = address.substr(0, colon);
  if (host.empty()) host = "0.0.0.0";
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  return ListenHostPort{std::move(host), port};
}

absl::StatusOr<std::unique_ptr<MetricsHttpServer>> MetricsHttpServer::Start(const std::string& address,
                                                                            std::function<std::string()> render_metrics,
                                                                            std::function<bool()> ready) {
  absl::StatusOr<ListenHostPort> parsed = ParseMetricsAddress(address);
  if (!parsed.ok()) return parsed.status();
  auto route = [render = std::move(render_metrics), ready = std::move(ready)](const HttpRequestHead& request) {
    HttpResponse response;
    if (request.path == "/metrics") {
      response.content_type = "text/plain; version=0.0.4; charset=utf-8";
      response.body = render();
    } else if (request.path == "/healthz") {
      response.body = "ok\n";
    } else if (request.path == "/readyz") {
      const bool is_ready = ready();
      response.status = is_ready ? 200 : 503;
      response.body = is_ready ? "ready\n" : "not serving\n";
    } else {
      response.status = 404;
      response.body = "not found: this port serves /metrics, /healthz and /readyz\n";
    }
    return response;
  };
  absl::StatusOr<std::unique_ptr<HttpListener>> listener =
      HttpListener::Start(parsed->host, parsed->port, std::move(route));
  if (!listener.ok()) {
    return absl::UnavailableError(absl::StrCat("--metrics_address \"", address, "\": could not listen (",
                                               listener.status().message(), "; ", kListenFailureCauses, ")"));
  }
  return std::unique_ptr<MetricsHttpServer>(new MetricsHttpServer(*std::move(listener)));
}

}  // namespace nupmpc::server
