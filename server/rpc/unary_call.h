#ifndef NUPMPC_SERVER_RPC_UNARY_CALL_H_
#define NUPMPC_SERVER_RPC_UNARY_CALL_H_

#include <atomic>
#include <functional>
#include <optional>
#include <string>
#include <type_traits>

#include "absl/status/status.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/grpc_handover.h"
#include "server/auth/caller.h"
#include "server/observability/log_context.h"
#include "server/rpc/catch_exceptions.h"
#include "server/rpc/raw_messages.h"
#include "server/sessions/step_solver.h"
#include "server/state/server_state.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {

// Which RPC a request type belongs to (the label of its error counter).
template <class Request>
struct RpcOf;
template <>
struct RpcOf<v1::CreateSessionRequest> : std::integral_constant<Rpc, Rpc::kCreateSession> {};
template <>
struct RpcOf<v1::SolveRequest> : std::integral_constant<Rpc, Rpc::kSolve> {};
template <>
struct RpcOf<v1::SolveOnceRequest> : std::integral_constant<Rpc, Rpc::kSolveOnce> {};
template <>
struct RpcOf<v1::GetSessionRequest> : std::integral_constant<Rpc, Rpc::kGetSession> {};
template <>
struct RpcOf<v1::ListSessionsRequest> : std::integral_constant<Rpc, Rpc::kListSessions> {};
template <>
struct RpcOf<v1::CloseSessionRequest> : std::integral_constant<Rpc, Rpc::kCloseSession> {};
template <>
struct RpcOf<v1::GetServerInfoRequest> : std::integral_constant<Rpc, Rpc::kGetServerInfo> {};
template <>
struct RpcOf<v1::FitGpModelRequest> : std::integral_constant<Rpc, Rpc::kFitGpModel> {};
template <>
struct RpcOf<v1::SolveFleetRequest> : std::integral_constant<Rpc, Rpc::kSolveFleet> {};

// One unary call of MpcService, taken as raw bytes (server/rpc/raw_messages.h): bytes that do
// not parse are answered with INVALID_ARGUMENT naming the expected type. The call owns its
// request and response and deletes itself when gRPC is done with it.
template <class Request, class Response>
class UnaryCall final : public grpc::ServerUnaryReactor {
 public:
  // A new call; when the bytes do not parse it has already finished, and Parsed() is false.
  static UnaryCall* Start(ServerState* state, grpc::CallbackServerContext* context, const grpc::ByteBuffer* raw_request,
                          grpc::ByteBuffer* raw_response) {
    auto* call = new UnaryCall(state, context, raw_response);
    state->work_in_flight.fetch_add(1);    // until Reply
    grpc::ByteBuffer bytes(*raw_request);  // parsing consumes its buffer
    const absl::Status parsed = ParseRaw(&bytes, &call->request_);
    call->parsed_ = parsed.ok();
    if (!call->parsed_) call->Reply(parsed);
    HandToGrpc(call);  // gRPC may cancel it from now on
    return call;
  }

  bool Parsed() const { return parsed_; }
  ServerState* state() const { return state_; }
  // The call's deadline and cancellation flag, for work that runs outside RunOnPool.
  const CallContext& Context() {
    call_.deadline = SteadyDeadline(*context_);
    call_.cancel = &cancelled_;
    call_.received_at = started_at_;
    return call_;
  }
  const Request& request() const { return request_; }
  Response* response() { return &response_; }

  // Sends the response (when `status` is OK) or the error; one access-log line at debug.
  void Reply(const absl::Status& status) {
    const grpc::Status sent =
        state_->ToGrpc(RpcOf<Request>::value, status.ok() ? SerializeRaw(response_, raw_response_) : status);
    if (spdlog::should_log(spdlog::level::debug)) LogAccess(sent);
    state_->work_in_flight.fetch_sub(1);
    HandToGrpc(this);
    Finish(sent);
  }

  // Runs `work` on the worker pool (RESOURCE_EXHAUSTED when the queue is full), through
  // `session`'s strand when given (one at a time per session), catching what escapes it.
  // `solve_result`: where `work` writes a solve's result, recorded in the solve metrics
  // when the work succeeds (nullptr: not a solve). A client that cancels raises the flag
  // the solver checks. `step`: the session's step this work solves, whose deadline orders
  // the pool's queue (step_deadline.h).
  void RunOnPool(const char* name, const v1::SolveResult* solve_result,
                 std::function<absl::Status(const CallContext&)> work, const SessionEntry* session = nullptr,
                 const v1::Step* step = nullptr) {
    if (state_->draining.load()) {
      Reply(absl::UnavailableError("the server is shutting down"));
      return;
    }
    Context();
    const std::optional<Clock::time_point> due =
        session != nullptr && step != nullptr ? StepDue(session->timing, *step, started_at_) : std::nullopt;
    const auto queued_at = Clock::now();
    auto run = [this, name, solve_result, work = std::move(work), queued_at, session] {
      const auto started_at = Clock::now();
      const absl::Status status = RunCatchingExceptions(name, [&] { return work(call_); });
      if (status.ok() && solve_result != nullptr) {
        state_->RecordSolve(*solve_result, session, std::chrono::duration<double>(started_at - queued_at).count(),
                            std::chrono::duration<double>(Clock::now() - queued_at).count());
      }
      Reply(status);
    };
    const absl::Status queued =
        session == nullptr
            ? state_->pool.TrySubmit(std::move(run))
            : SessionStrand::Submit(session->strand, state_->pool,
                                    {.run = std::move(run),
                                     .fail = [this](absl::Status s) { Reply(s); },
                                     .expected_ms = session->last_solve_ms.load(std::memory_order_relaxed),
                                     .due = due});
    if (!queued.ok()) Reply(queued);
  }

  void OnCancel() override {
    TakeFromGrpc(this);
    cancelled_.store(true);
  }
  void OnDone() override {
    TakeFromGrpc(this);
    HandToGrpc(state_);  // before grpc::Server::Shutdown returns (GrpcServer::Shutdown)
    delete this;
  }

 private:
  void LogAccess(const grpc::Status& sent) const {
    std::string session;
    if constexpr (requires { request_.session_id(); }) session = request_.session_id();
    if constexpr (requires { response_.session_id(); }) {
      if (session.empty()) session = response_.session_id();
    }
    // A malformed id is the client's text: shown escaped and cut short.
    if (!session.empty() && !CheckSessionIdForm(session).ok()) session = QuoteSessionId(session);
    const Caller caller = CallerOf(*context_, state_->auth.get());
    const LogContext log_context(session, caller.principal);
    spdlog::debug("access: {} {} {:.3f} ms peer {}", std::string(RpcName(RpcOf<Request>::value)),
                  absl::StatusCodeToString(static_cast<absl::StatusCode>(sent.error_code())),
                  std::chrono::duration<double, std::milli>(Clock::now() - started_at_).count(), caller.connection);
  }

  UnaryCall(ServerState* state, grpc::CallbackServerContext* context, grpc::ByteBuffer* raw_response)
      : state_(state), context_(context), raw_response_(raw_response) {}

  const Clock::time_point started_at_ = Clock::now();
  ServerState* const state_;
  grpc::CallbackServerContext* const context_;
  grpc::ByteBuffer* const raw_response_;
  Request request_;
  Response response_;
  bool parsed_ = false;
  CallContext call_;
  std::atomic<bool> cancelled_{false};
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_RPC_UNARY_CALL_H_
