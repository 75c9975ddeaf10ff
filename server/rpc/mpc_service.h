#ifndef NUPMPC_SERVER_RPC_MPC_SERVICE_H_
#define NUPMPC_SERVER_RPC_MPC_SERVICE_H_

#include "nupmpc/v1/nupmpc.grpc.pb.h"
#include "server/state/server_state.h"

namespace nupmpc::server {

// Every method takes its requests as raw bytes (server/rpc/raw_messages.h): a request that does
// not parse gets INVALID_ARGUMENT with a message instead of gRPC's bare UNIMPLEMENTED.
using MpcServiceBase = v1::MpcService::WithRawCallbackMethod_CreateSession<
    v1::MpcService::WithRawCallbackMethod_Control<v1::MpcService::WithRawCallbackMethod_Solve<
        v1::MpcService::WithRawCallbackMethod_SolveOnce<v1::MpcService::WithRawCallbackMethod_GetSession<
            v1::MpcService::WithRawCallbackMethod_ListSessions<v1::MpcService::WithRawCallbackMethod_CloseSession<
                v1::MpcService::WithRawCallbackMethod_GetServerInfo<v1::MpcService::WithRawCallbackMethod_FitGpModel<
                    v1::MpcService::WithRawCallbackMethod_SolveFleet<v1::MpcService::Service>>>>>>>>>>;

// nupmpc.v1.MpcService on gRPC's callback API. Reactions never block: solves (and session
// creation, which is O(N) work) run on the worker pool; lookups, listings and counters are
// answered inline.
class MpcServiceImpl final : public MpcServiceBase {
 public:
  explicit MpcServiceImpl(ServerState* state) : state_(state) {}

  using Raw = grpc::ByteBuffer;
  grpc::ServerUnaryReactor* CreateSession(grpc::CallbackServerContext* context, const Raw* request,
                                          Raw* response) override;
  grpc::ServerBidiReactor<Raw, Raw>* Control(grpc::CallbackServerContext* context) override;
  grpc::ServerUnaryReactor* Solve(grpc::CallbackServerContext* context, const Raw* request, Raw* response) override;
  grpc::ServerUnaryReactor* SolveOnce(grpc::CallbackServerContext* context, const Raw* request, Raw* response) override;
  grpc::ServerUnaryReactor* GetSession(grpc::CallbackServerContext* context, const Raw* request,
                                       Raw* response) override;
  grpc::ServerUnaryReactor* ListSessions(grpc::CallbackServerContext* context, const Raw* request,
                                         Raw* response) override;
  grpc::ServerUnaryReactor* CloseSession(grpc::CallbackServerContext* context, const Raw* request,
                                         Raw* response) override;
  grpc::ServerUnaryReactor* GetServerInfo(grpc::CallbackServerContext* context, const Raw* request,
                                          Raw* response) override;
  grpc::ServerUnaryReactor* FitGpModel(grpc::CallbackServerContext* context, const Raw* request,
                                       Raw* response) override;
  grpc::ServerUnaryReactor* SolveFleet(grpc::CallbackServerContext* context, const Raw* request,
                                       Raw* response) override;

 private:
  ServerState* state_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_RPC_MPC_SERVICE_H_
