#ifndef NUPMPC_SERVER_MPC_SERVICE_H_
#define NUPMPC_SERVER_MPC_SERVICE_H_

#include "nupmpc/v1/nupmpc.grpc.pb.h"
#include "server/server_context.h"

namespace nupmpc::server {

// nupmpc.v1.MpcService on gRPC's callback API. Reactions never block: solves (and session
// creation, which is O(N) work) run on the worker pool; lookups, listings and counters are
// answered inline.
class MpcServiceImpl final : public v1::MpcService::CallbackService {
 public:
  explicit MpcServiceImpl(ServerState* state) : state_(state) {}

  grpc::ServerUnaryReactor* CreateSession(grpc::CallbackServerContext* context, const v1::CreateSessionRequest* request,
                                          v1::CreateSessionResponse* response) override;
  grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse>* Control(
      grpc::CallbackServerContext* context) override;
  grpc::ServerUnaryReactor* Solve(grpc::CallbackServerContext* context, const v1::SolveRequest* request,
                                  v1::SolveResponse* response) override;
  grpc::ServerUnaryReactor* SolveOnce(grpc::CallbackServerContext* context, const v1::SolveOnceRequest* request,
                                      v1::SolveOnceResponse* response) override;
  grpc::ServerUnaryReactor* GetSession(grpc::CallbackServerContext* context, const v1::GetSessionRequest* request,
                                       v1::GetSessionResponse* response) override;
  grpc::ServerUnaryReactor* ListSessions(grpc::CallbackServerContext* context,
                                         const v1::ListSessionsRequest* request,
                                         v1::ListSessionsResponse* response) override;
  grpc::ServerUnaryReactor* CloseSession(grpc::CallbackServerContext* context,
                                         const v1::CloseSessionRequest* request,
                                         v1::CloseSessionResponse* response) override;
  grpc::ServerUnaryReactor* GetServerInfo(grpc::CallbackServerContext* context,
                                          const v1::GetServerInfoRequest* request,
                                          v1::GetServerInfoResponse* response) override;
  grpc::ServerUnaryReactor* FitGpModel(grpc::CallbackServerContext* context, const v1::FitGpModelRequest* request,
                                       v1::FitGpModelResponse* response) override;

 private:
  ServerState* state_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_MPC_SERVICE_H_
