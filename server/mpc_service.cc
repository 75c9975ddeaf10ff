#include "server/mpc_service.h"

#include <functional>

#include "absl/strings/ascii.h"
#include "core/platform/cpu_baseline.h"
#include "core/util/status_macros.h"
#include "server/control_stream.h"
#include "server/gp_conversion.h"
#include "server/process_memory.h"
#include "server/step_solver.h"
#include "server/version.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {
namespace {

// A unary call whose work runs on the worker pool. It finishes itself, and a client that
// cancels raises the flag the solver checks every iteration.
class PooledUnary : public grpc::ServerUnaryReactor {
 public:
  // Runs `work` on the pool (or answers RESOURCE_EXHAUSTED when the queue is full).
  // `is_solve`: count it in the solve counters and latency histogram. With a `session`,
  // the work goes through the session's strand (one at a time per session).
  static grpc::ServerUnaryReactor* Start(ServerState* state, grpc::CallbackServerContext* context, bool is_solve,
                                         std::function<absl::Status(const CallContext&)> work,
                                         const SessionEntry* session = nullptr) {
    auto* self = new PooledUnary();
    if (state->draining.load()) {
      self->Finish(state->ToGrpc(absl::UnavailableError("the server is shutting down")));
      return self;
    }
    self->call_.deadline = SteadyDeadline(*context);
    self->call_.cancel = &self->cancelled_;
    const auto queued_at = Clock::now();
    auto run = [self, state, is_solve, work = std::move(work), queued_at] {
      const absl::Status status = work(self->call_);
      if (status.ok() && is_solve) {
        state->metrics.RecordSolve(std::chrono::duration<double, std::milli>(Clock::now() - queued_at).count());
      }
      self->Finish(state->ToGrpc(status));
    };
    const absl::Status queued =
        session == nullptr
            ? state->pool.TrySubmit(std::move(run))
            : SessionStrand::Submit(session->strand, state->pool,
                                    {std::move(run), [self, state](absl::Status s) { self->Finish(state->ToGrpc(s)); },
                                     session->last_solve_ms.load(std::memory_order_relaxed)});
    if (!queued.ok()) self->Finish(state->ToGrpc(queued));
    return self;
  }

  void OnCancel() override { cancelled_.store(true); }
  void OnDone() override { delete this; }

 private:
  PooledUnary() = default;
  CallContext call_;
  std::atomic<bool> cancelled_{false};
};

grpc::ServerUnaryReactor* FinishNow(grpc::CallbackServerContext* context, const grpc::Status& status) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  reactor->Finish(status);
  return reactor;
}

}  // namespace

grpc::ServerUnaryReactor* MpcServiceImpl::CreateSession(grpc::CallbackServerContext* context,
                                                        const v1::CreateSessionRequest* request,
                                                        v1::CreateSessionResponse* response) {
  ServerState* state = state_;
  return PooledUnary::Start(state, context, /*is_solve=*/false,
                            [state, request, response](const CallContext& call) -> absl::Status {
    absl::StatusOr<BuiltSession> built =
        BuildSession(request->spec(), state->options.size_limits, &state->gp_models, &call);
    if (!built.ok()) return built.status();
    absl::StatusOr<std::shared_ptr<SessionEntry>> entry =
        state->registry.Add(std::move(built->solver), built->default_time_limit_ms,
                            /*owned_by_stream=*/false, std::move(built->transform));
    if (!entry.ok()) return entry.status();
    response->set_session_id((*entry)->id);
    *response->mutable_dimensions() = (*entry)->dims;
    response->set_algorithm(AlgorithmToProto((*entry)->algorithm.load()));
    state->FillLimits(response->mutable_limits());
    spdlog::info("session {} created (M={}, L={}, K={}, N={})", (*entry)->id, response->dimensions().num_states(),
                 response->dimensions().num_inputs(), response->dimensions().num_outputs(),
                 response->dimensions().horizon());
    return absl::OkStatus();
  });
}

grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse>* MpcServiceImpl::Control(
    grpc::CallbackServerContext* context) {
  return ControlStream::Start(state_, context);
}

grpc::ServerUnaryReactor* MpcServiceImpl::Solve(grpc::CallbackServerContext* context, const v1::SolveRequest* request,
                                                v1::SolveResponse* response) {
  absl::StatusOr<std::shared_ptr<SessionEntry>> entry = state_->registry.Find(request->session_id());
  if (!entry.ok()) return FinishNow(context, state_->ToGrpc(entry.status()));
  if ((*entry)->attached.load()) {
    return FinishNow(context, state_->ToGrpc(absl::FailedPreconditionError(
                                  "session_id: a Control stream is attached to this session; send steps there")));
  }
  const SessionEntry* session = entry->get();
  return PooledUnary::Start(
      state_, context, /*is_solve=*/true,
      [entry = *std::move(entry), request, response](const CallContext& call) {
        return SolveStep(*entry, request->step(), call, response->mutable_result());
      },
      session);
}

grpc::ServerUnaryReactor* MpcServiceImpl::SolveOnce(grpc::CallbackServerContext* context,
                                                    const v1::SolveOnceRequest* request,
                                                    v1::SolveOnceResponse* response) {
  ServerState* state = state_;
  return PooledUnary::Start(state, context, /*is_solve=*/true, [state, request, response](const CallContext& call) {
    return server::SolveOnce(request->spec(), state->options.size_limits, call, response->mutable_result(),
                             &state->gp_models);
  });
}

grpc::ServerUnaryReactor* MpcServiceImpl::GetSession(grpc::CallbackServerContext* context,
                                                     const v1::GetSessionRequest* request,
                                                     v1::GetSessionResponse* response) {
  absl::StatusOr<std::shared_ptr<SessionEntry>> entry = state_->registry.Find(request->session_id());
  if (!entry.ok()) return FinishNow(context, state_->ToGrpc(entry.status()));
  (*entry)->Describe(response->mutable_session());
  return FinishNow(context, grpc::Status::OK);
}

grpc::ServerUnaryReactor* MpcServiceImpl::ListSessions(grpc::CallbackServerContext* context,
                                                       const v1::ListSessionsRequest*,
                                                       v1::ListSessionsResponse* response) {
  for (const auto& entry : state_->registry.List()) entry->Describe(response->add_sessions());
  return FinishNow(context, grpc::Status::OK);
}

grpc::ServerUnaryReactor* MpcServiceImpl::CloseSession(grpc::CallbackServerContext* context,
                                                       const v1::CloseSessionRequest* request,
                                                       v1::CloseSessionResponse*) {
  absl::StatusOr<std::shared_ptr<SessionEntry>> entry = state_->registry.Find(request->session_id());
  if (entry.ok() && (*entry)->owned_by_stream) {
    return FinishNow(context, state_->ToGrpc(absl::FailedPreconditionError(
                                  "session_id: the session belongs to a Control stream and closes with it")));
  }
  const absl::Status status = state_->registry.Close(request->session_id());
  if (status.ok()) spdlog::info("session {} closed", request->session_id());
  return FinishNow(context, state_->ToGrpc(status));
}

grpc::ServerUnaryReactor* MpcServiceImpl::GetServerInfo(grpc::CallbackServerContext* context,
                                                        const v1::GetServerInfoRequest*,
                                                        v1::GetServerInfoResponse* response) {
  response->set_version(kVersion);
  response->set_api_version("nupmpc.v1");
  state_->FillLimits(response->mutable_limits());
  for (v1::Algorithm a : {v1::ALGORITHM_IAKE, v1::ALGORITHM_IBFFD, v1::ALGORITHM_IFFBDD}) response->add_algorithms(a);
  state_->metrics.Fill(response);
  response->set_active_sessions(state_->registry.size());
  response->set_draining(state_->draining.load());
  response->set_resident_memory_bytes(ResidentMemoryBytes());
  response->set_cpu_baseline(platform::kBuildCpuBaseline);
  response->set_cpu_features(std::string(absl::StripLeadingAsciiWhitespace(platform::kBuildCpuFeatures)));
  return FinishNow(context, grpc::Status::OK);
}

grpc::ServerUnaryReactor* MpcServiceImpl::FitGpModel(grpc::CallbackServerContext* context,
                                                     const v1::FitGpModelRequest* request,
                                                     v1::FitGpModelResponse* response) {
  // O(P³) per iteration: on the pool like a solve, never in the reaction.
  ServerState* state = state_;
  return PooledUnary::Start(state, context, /*is_solve=*/false,
                            [state, request, response](const CallContext& call) -> absl::Status {
    NUPMPC_ASSIGN_OR_RETURN(const gp::FitOptions fit_limits, FitLimits(&call));
    return server::FitGpModel(*request, state->options.size_limits, fit_limits, response);
  });
}

}  // namespace nupmpc::server
