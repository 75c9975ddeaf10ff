#ifndef NUPMPC_LOADTEST_ECHO_SERVER_H_
#define NUPMPC_LOADTEST_ECHO_SERVER_H_

// The peers of the load test: stand-ins for nupmpc-server's Control stream on a loopback
// port (nupmpc-loadtest runs each in a child process, EchoProcess). The echo answers the
// first message with a session id and every step at once, inside the gRPC reaction, with
// one fixed real answer (the plan the real server returned for the instance, so the
// messages have the real sizes). The same load level against it measures what gRPC and
// this machine's loopback cost for exactly this traffic, with the load generator on the
// same cores: the gap between it and the real server is nupmpc's own cost (solve,
// hand-over to the worker pool, validation, conversion). The inline peer is the echo busy
// for each step's solve time; the bare peer (StartSolving) really solves.

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"

namespace nupmpc::loadtest {

class EchoControlServer {
 public:
  // Listens on 127.0.0.1 at a free port; every step is answered with `answer`, after
  // busy-waiting inside the reaction: a stream's k-th step for busy[k % busy.size()] of the
  // thread's CPU time (none when `busy` is empty), a solve of that length done where the
  // request arrives with no hand-over to a worker, the lowest round trip any server could
  // have for that work.
  // nupmpc-loadtest passes the core's own time for each closed-loop state, in the order
  // its streams send them.
  static absl::StatusOr<std::unique_ptr<EchoControlServer>> Start(v1::SolveResult answer,
                                                                  std::vector<std::chrono::nanoseconds> busy = {});
  // The bare peer: a server reduced to the real work, in the reaction. Each stream's first
  // message builds its session from the spec it carries; each step is solved right there as
  // nupmpc-server's SolveStep does (converted, applied, warm start shifted, solved, the
  // result converted) and answered, with no worker pool, session registry, admission,
  // deadlines, metrics or logging. Its round trip against nupmpc-server's is what the
  // server's own machinery costs for the same solves on the same cores.
  static absl::StatusOr<std::unique_ptr<EchoControlServer>> StartSolving();
  ~EchoControlServer();

  std::string target() const;

 private:
  class Service;
  EchoControlServer() = default;
  static absl::StatusOr<std::unique_ptr<EchoControlServer>> Listen(std::unique_ptr<Service> service);
  std::unique_ptr<Service> service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
};

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_ECHO_SERVER_H_
