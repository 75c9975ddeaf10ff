#include "server/rpc/mpc_service.h"

#include "absl/strings/ascii.h"
#include "core/public/cpu_baseline.h"
#include "core/public/status_macros.h"
#include "server/convert/gp_conversion.h"
#include "server/convert/result_conversion.h"
#include "server/convert/session_cost.h"
#include "server/observability/log_context.h"
#include "server/observability/process_memory.h"
#include "server/observability/version.h"
#include "server/rpc/control_stream.h"
#include "server/rpc/fleet_call.h"
#include "server/rpc/unary_call.h"
#include "server/scheduling/cpu_affinity.h"
#include "server/sessions/session_factory.h"
#include "server/sessions/step_solver.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {
namespace {

// A Solve for a session the server holds only as a snapshot (--state_dir): restored on a
// worker (building a session is no work for gRPC's threads), then solved there. The
// restored session is new to the registry; should another call of it have got there in
// between, this one is answered ABORTED (retryable) rather than waiting for it.
void SolveRestoring(UnaryCall<v1::SolveRequest, v1::SolveResponse>* call, const Caller& caller) {
  ServerState* state = call->state();
  const v1::SolveRequest* request = &call->request();
  v1::SolveResult* result = call->response()->mutable_result();
  call->RunOnPool("Solve", result, [state, request, caller, result](const CallContext& context) {
    NUPMPC_ASSIGN_OR_RETURN(const std::shared_ptr<SessionEntry> entry,
                            state->FindOrRestore(request->session_id(), caller, /*by_control_stream=*/false));
    absl::Status solved = absl::AbortedError("session_id: the session was just restored and is busy; retry");
    SessionStrand::RunNowIfIdle(entry->strand, state->pool, [&] {
      solved = entry->UnaryStepsRefused();
      if (solved.ok()) solved = SolveStep(*entry, request->step(), context, result);
    });
    return solved;
  });
}

}  // namespace

grpc::ServerUnaryReactor* MpcServiceImpl::CreateSession(grpc::CallbackServerContext* context, const Raw* raw_request,
                                                        Raw* raw_response) {
  auto* call =
      UnaryCall<v1::CreateSessionRequest, v1::CreateSessionResponse>::Start(state_, context, raw_request, raw_response);
  if (!call->Parsed()) return call;
  if (const std::string& requested = call->request().session_id(); !requested.empty()) {
    if (absl::Status form = CheckRequestedSessionId(requested); !form.ok()) {
      call->Reply(form);
      return call;
    }
  }
  ServerState* state = state_;
  const v1::CreateSessionRequest* request = &call->request();
  v1::CreateSessionResponse* response = call->response();
  call->RunOnPool(
      "CreateSession", /*solve_result=*/nullptr,
      [state, request, response, owner = OwnerFor(CallerOf(*context, state_->auth.get()))](const CallContext& c) {
        absl::StatusOr<std::shared_ptr<SessionEntry>> entry =
            CreateAndRegister(request->spec(), state->options.size_limits, &state->gp_models, &state->budget,
                              &state->registry, c, /*owned_by_stream=*/false, request->session_id(), owner,
                              /*keep_spec=*/state->snapshots != nullptr);
        if (!entry.ok()) return entry.status();
        response->set_session_id((*entry)->id);
        *response->mutable_dimensions() = (*entry)->dims;
        response->set_algorithm(AlgorithmToProto((*entry)->algorithm.load()));
        state->FillLimits(response->mutable_limits());
        const LogContext log_context((*entry)->id, (*entry)->owner.principal);
        spdlog::info("session {} created (M={}, L={}, K={}, N={}); memory budget: {} MiB reserved of {} MiB",
                     (*entry)->id, response->dimensions().num_states(), response->dimensions().num_inputs(),
                     response->dimensions().num_outputs(), response->dimensions().horizon(),
                     state->budget.reserved() >> 20, state->budget.capacity() >> 20);
        return absl::OkStatus();
      });
  return call;
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* MpcServiceImpl::Control(
    grpc::CallbackServerContext* context) {
  return ControlStream::Start(state_, context);
}

grpc::ServerUnaryReactor* MpcServiceImpl::Solve(grpc::CallbackServerContext* context, const Raw* raw_request,
                                                Raw* raw_response) {
  auto* call = UnaryCall<v1::SolveRequest, v1::SolveResponse>::Start(state_, context, raw_request, raw_response);
  if (!call->Parsed()) return call;
  const Caller caller = CallerOf(*context, state_->auth.get());
  absl::StatusOr<std::shared_ptr<SessionEntry>> entry = state_->registry.Find(call->request().session_id(), caller);
  if (!entry.ok() && state_->MayRestore(call->request().session_id(), caller)) {
    SolveRestoring(call, caller);
    return call;
  }
  if (!entry.ok()) {
    call->Reply(entry.status());
    return call;
  }
  if (const absl::Status refused = (*entry)->UnaryStepsRefused(); !refused.ok()) {
    call->Reply(refused);
    return call;
  }
  const SessionEntry* session = entry->get();
  const v1::Step* step = &call->request().step();
  v1::SolveResult* result = call->response()->mutable_result();
  call->RunOnPool(
      "Solve", result,
      [entry = *std::move(entry), step, result](const CallContext& c) { return SolveStep(*entry, *step, c, result); },
      session, step);
  return call;
}

grpc::ServerUnaryReactor* MpcServiceImpl::SolveOnce(grpc::CallbackServerContext* context, const Raw* raw_request,
                                                    Raw* raw_response) {
  auto* call =
      UnaryCall<v1::SolveOnceRequest, v1::SolveOnceResponse>::Start(state_, context, raw_request, raw_response);
  if (!call->Parsed()) return call;
  ServerState* state = state_;
  const v1::ProblemSpec* spec = &call->request().spec();
  v1::SolveResult* result = call->response()->mutable_result();
  call->RunOnPool("SolveOnce", result, [state, spec, result](const CallContext& c) {
    return server::SolveOnce(*spec, state->options.size_limits, c, result, &state->gp_models, &state->budget);
  });
  return call;
}

grpc::ServerUnaryReactor* MpcServiceImpl::GetSession(grpc::CallbackServerContext* context, const Raw* raw_request,
                                                     Raw* raw_response) {
  auto* call =
      UnaryCall<v1::GetSessionRequest, v1::GetSessionResponse>::Start(state_, context, raw_request, raw_response);
  if (!call->Parsed()) return call;
  absl::StatusOr<std::shared_ptr<SessionEntry>> entry =
      state_->registry.Find(call->request().session_id(), CallerOf(*context, state_->auth.get()));
  if (entry.ok()) (*entry)->Describe(call->response()->mutable_session());
  call->Reply(entry.status());
  return call;
}

grpc::ServerUnaryReactor* MpcServiceImpl::ListSessions(grpc::CallbackServerContext* context, const Raw* raw_request,
                                                       Raw* raw_response) {
  auto* call =
      UnaryCall<v1::ListSessionsRequest, v1::ListSessionsResponse>::Start(state_, context, raw_request, raw_response);
  if (!call->Parsed()) return call;
  for (const auto& entry :
       state_->registry.ListFor(CallerOf(*context, state_->auth.get()), state_->options.list_all_sessions)) {
    entry->Describe(call->response()->add_sessions());
  }
  call->Reply(absl::OkStatus());
  return call;
}

grpc::ServerUnaryReactor* MpcServiceImpl::CloseSession(grpc::CallbackServerContext* context, const Raw* raw_request,
                                                       Raw* raw_response) {
  auto* call =
      UnaryCall<v1::CloseSessionRequest, v1::CloseSessionResponse>::Start(state_, context, raw_request, raw_response);
  if (!call->Parsed()) return call;
  const std::string& id = call->request().session_id();
  const Caller caller = CallerOf(*context, state_->auth.get());
  absl::StatusOr<std::shared_ptr<SessionEntry>> entry = state_->registry.Find(id, caller);
  if (!entry.ok() && state_->MayRestore(id, caller)) {
    // A session still in the state directory: closing it is discarding its snapshot. The
    // claim reads and checks the whole file, so it runs on the pool, not on gRPC's thread.
    call->RunOnPool("CloseSession", /*solve_result=*/nullptr,
                    [state = state_, id, caller, not_found = entry.status()](const CallContext&) {
                      return state->snapshots->Claim(id, caller, /*by_control_stream=*/false).ok() ? absl::OkStatus()
                                                                                                   : not_found;
                    });
    return call;
  }
  if (!entry.ok()) {
    call->Reply(entry.status());
    return call;
  }
  if ((*entry)->owned_by_stream) {
    call->Reply(
        absl::FailedPreconditionError("session_id: the session belongs to a Control stream and closes with it"));
    return call;
  }
  // Answered once the session's memory is given back (after a solve in flight).
  const absl::Status status = state_->registry.Close(id, [state = state_, call, id, entry = *entry] {
    const LogContext log_context(id, entry->owner.principal);
    spdlog::info("session {} closed; memory budget: {} MiB reserved of {} MiB", id, state->budget.reserved() >> 20,
                 state->budget.capacity() >> 20);
    call->Reply(absl::OkStatus());
  });
  if (!status.ok()) call->Reply(status);
  return call;
}

grpc::ServerUnaryReactor* MpcServiceImpl::GetServerInfo(grpc::CallbackServerContext* context, const Raw* raw_request,
                                                        Raw* raw_response) {
  auto* call =
      UnaryCall<v1::GetServerInfoRequest, v1::GetServerInfoResponse>::Start(state_, context, raw_request, raw_response);
  if (!call->Parsed()) return call;
  v1::GetServerInfoResponse* response = call->response();
  response->set_version(kVersion);
  response->set_api_version("nupmpc.v1");
  state_->FillLimits(response->mutable_limits());
  for (v1::Algorithm a : {v1::ALGORITHM_IAKE, v1::ALGORITHM_IBFFD, v1::ALGORITHM_IFFBDD}) response->add_algorithms(a);
  state_->metrics.Fill(response);
  response->set_active_sessions(state_->registry.size());
  response->set_draining(!state_->serving.load());
  response->set_resident_memory_bytes(ResidentMemoryBytes());
  response->set_cpu_baseline(platform::kBuildCpuBaseline);
  response->set_cpu_features(std::string(absl::StripLeadingAsciiWhitespace(platform::kBuildCpuFeatures)));
  response->set_memory_reserved_bytes(static_cast<std::uint64_t>(state_->budget.reserved()));
  response->set_control_streams(static_cast<std::uint32_t>(state_->control_streams.load()));
  response->set_control_stream_read_pauses(state_->stream_read_pauses.load(std::memory_order_relaxed));
  response->set_cpus(CallingThreadCpuList());
  response->set_solves_in_place(state_->pool.run_here());
  call->Reply(absl::OkStatus());
  return call;
}

grpc::ServerUnaryReactor* MpcServiceImpl::FitGpModel(grpc::CallbackServerContext* context, const Raw* raw_request,
                                                     Raw* raw_response) {
  auto* call =
      UnaryCall<v1::FitGpModelRequest, v1::FitGpModelResponse>::Start(state_, context, raw_request, raw_response);
  if (!call->Parsed()) return call;
  ServerState* state = state_;
  const v1::FitGpModelRequest* request = &call->request();
  v1::FitGpModelResponse* response = call->response();
  // O(P³) per iteration: on the pool like a solve, never in the reaction; its O(P²)
  // matrices are reserved in the memory budget first.
  call->RunOnPool("FitGpModel", /*solve_result=*/nullptr,
                  [state, request, response](const CallContext& c) -> absl::Status {
                    NUPMPC_ASSIGN_OR_RETURN(const gp::FitOptions fit_limits, FitLimits(&c));
                    NUPMPC_ASSIGN_OR_RETURN(const std::int64_t fit_bytes,
                                            GpFitBytes(request->model(), "model", state->options.size_limits));
                    NUPMPC_ASSIGN_OR_RETURN(const MemoryBudget::Reservation reserved,
                                            state->budget.Reserve(fit_bytes, "model (the fit's kernel matrices)"));
                    return server::FitGpModel(*request, state->options.size_limits, fit_limits, response);
                  });
  return call;
}

grpc::ServerUnaryReactor* MpcServiceImpl::SolveFleet(grpc::CallbackServerContext* context, const Raw* raw_request,
                                                     Raw* raw_response) {
  auto* call = FleetCall::Start(state_, context, raw_request, raw_response);
  if (!call->Parsed()) return call;
  StartFleet(call, CallerOf(*context, state_->auth.get()));
  return call;
}

}  // namespace nupmpc::server
