#ifndef NUPMPC_SERVER_GRPC_SERVER_H_
#define NUPMPC_SERVER_GRPC_SERVER_H_

#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>

#include "absl/status/statusor.h"
#include "grpcpp/grpcpp.h"
#include "server/metrics_http.h"
#include "server/rpc/mpc_service.h"
#include "server/state/server_state.h"

namespace nupmpc::server {

// The whole server: MpcService, grpc.health.v1, reflection, the idle-session janitor.
// Used by nupmpc-server's main and, in-process, by the integration tests.
class GrpcServer {
 public:
  static absl::StatusOr<std::unique_ptr<GrpcServer>> Start(const ServerOptions& options);
  ~GrpcServer();

  int port() const { return port_; }
  // The metrics endpoint's port (0: none, ServerOptions::metrics_address empty).
  int metrics_port() const { return metrics_ != nullptr ? metrics_->port() : 0; }
  ServerState& state() { return *state_; }
  // The first step of a stop behind a load balancer: grpc.health.v1 says NOT_SERVING (the
  // balancer's checks move new calls away) while every call is still served.
  void ReportNotServing();
  // Graceful stop: refuse new work (UNAVAILABLE, health NOT_SERVING), give in-flight calls
  // `grace_period_s` to finish, cancel the rest, stop the workers. Idempotent.
  void Shutdown();
  void Wait() { server_->Wait(); }

 private:
  GrpcServer() = default;
  void Janitor();
  // Takes in a changed --auth_tokens_file (the janitor checks once a second).
  void ReloadTokens();
  // Ends the open Control streams of callers whose token is no longer in the tokens file
  // (new calls of theirs are refused by authentication).
  void RevokeStreamsWithoutAccess();

  std::unique_ptr<ServerState> state_;
  std::unique_ptr<MpcServiceImpl> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<MetricsHttpServer> metrics_;
  int port_ = 0;
  std::mutex janitor_mu_;
  std::condition_variable janitor_wake_;
  bool stopping_ = false;
  std::thread janitor_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_GRPC_SERVER_H_
