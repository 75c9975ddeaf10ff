// Fuzz target (c): a sequence of ControlRequests on one Control stream of an in-process
// server: the real ControlStream reactor behind gRPC on a loopback port, with the fuzz
// targets' size limits. The input (tests/fuzz/control_sequence.h) chooses the requests, whether
// the client reads in lock-step or only at the end, and whether it half-closes or cancels.
// Properties: no crash or sanitizer report; every answer carries a finite plan or an error
// with a message; the stream ends with a status before a deadline (no hang); and once it
// has ended the server holds nothing of it: no open stream, no session (every session a
// Control stream creates belongs to it and closes with it).
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include "client/channel_factory.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"
#include "server/grpc_server.h"
#include "spdlog/spdlog.h"
#include "tests/fuzz/control_sequence.h"
#include "tests/fuzz/fuzz_limits.h"

namespace {

using nupmpc::fuzz::Violated;
using nupmpc::server::GrpcServer;

GrpcServer& Server() {
  static GrpcServer* server = [] {
    spdlog::set_level(spdlog::level::off);  // session lifecycle lines for every input
    nupmpc::server::ServerOptions options;
    options.address = "127.0.0.1:0";
    options.size_limits = nupmpc::fuzz::SmallLimits();
    absl::StatusOr<std::unique_ptr<GrpcServer>> started = GrpcServer::Start(options);
    if (!started.ok()) Violated("the in-process server does not start");
    return started->release();  // lives for the whole run, like a deployed server
  }();
  return *server;
}

nupmpc::v1::MpcService::Stub& Stub() {
  static std::unique_ptr<nupmpc::v1::MpcService::Stub> stub =
      nupmpc::v1::MpcService::NewStub(nupmpc::OpenChannel("127.0.0.1:" + std::to_string(Server().port())));
  return *stub;
}

void CheckAnswer(const nupmpc::v1::ControlResponse& answer) {
  if (answer.error_code() != 0 && answer.error_message().empty()) Violated("an error answer without a message");
  if (answer.has_result()) nupmpc::fuzz::CheckResult(answer.result());
}

// The server's bookkeeping of a stream (the open-stream count, the session it owned) is
// released in the reactor's OnDone, which gRPC may run just after the client saw the status.
void CheckNothingLeftOfTheStream() {
  nupmpc::server::ServerState& state = Server().state();
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (state.control_streams.load() != 0 || state.registry.size() != 0) {
    if (std::chrono::steady_clock::now() > until) Violated("a Control stream or its session outlived the call");
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nupmpc::fuzz::ControlSequence sequence = nupmpc::fuzz::DecodeControlSequence(data, size);
  if (sequence.requests.empty()) return 0;
  for (nupmpc::v1::ControlRequest& request : sequence.requests) {
    // Bounded work per input: a few iterations per solve (as spec_solve_fuzzer's cap).
    if (request.has_step()) {
      nupmpc::v1::Step* step = request.mutable_step();
      if (step->max_iterations() == 0 || step->max_iterations() > 20) step->set_max_iterations(20);
    }
    if (request.has_spec()) request.mutable_spec()->mutable_options()->set_max_iterations(20);
  }
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  auto stream = Stub().Control(&context);
  nupmpc::v1::ControlResponse answer;
  bool open = true;
  for (const nupmpc::v1::ControlRequest& request : sequence.requests) {
    if (!stream->Write(request)) break;  // the server ended the stream
    if (sequence.lock_step) {
      if (!stream->Read(&answer)) break;
      CheckAnswer(answer);
    }
  }
  if (sequence.cancel_at_end) {
    context.TryCancel();
  } else {
    stream->WritesDone();
    while (open) {
      open = stream->Read(&answer);
      if (open) CheckAnswer(answer);
    }
  }
  const grpc::Status status = stream->Finish();
  if (status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) Violated("a Control stream did not end in 10 s");
  if (!status.ok() && status.error_message().empty()) Violated("a stream ended with an error without a message");
  CheckNothingLeftOfTheStream();
  return 0;
}
