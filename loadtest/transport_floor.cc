#include "loadtest/transport_floor.h"

#include <chrono>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/channel_factory.h"
#include "grpcpp/generic/generic_stub.h"
#include "grpcpp/grpcpp.h"
#include "loadtest/quantile.h"

namespace nupmpc::loadtest {
namespace {

constexpr char kHealthCheck[] = "/grpc.health.v1.Health/Check";
constexpr int kWarmUpCalls = 20;

// One unary call with raw bytes: the request is an empty HealthCheckRequest (service "",
// zero bytes on the wire), so no health proto stubs are needed.
grpc::Status Check(grpc::GenericStub& stub, grpc::CompletionQueue& cq) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  grpc::Slice no_fields("");  // a buffer holding zero bytes, not a missing message
  const grpc::ByteBuffer request(&no_fields, 1);
  grpc::ByteBuffer response;
  grpc::Status status;
  std::unique_ptr<grpc::GenericClientAsyncResponseReader> call =
      stub.PrepareUnaryCall(&context, kHealthCheck, request, &cq);
  call->StartCall();
  call->Finish(&response, &status, &context);
  void* tag = nullptr;
  bool ok = false;
  if (!cq.Next(&tag, &ok) || !ok) return grpc::Status(grpc::StatusCode::UNKNOWN, "completion queue failed");
  return status;
}

}  // namespace

absl::StatusOr<TransportFloor> MeasureTransportFloor(const std::string& target, int calls,
                                                     const ChannelSecurity& security) {
  ChannelOptions options;
  options.own_connection = true;  // not shared with the streams' channels
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel = OpenChannel(target, security, options);
  if (!channel.ok()) return channel.status();
  grpc::GenericStub stub(*std::move(channel));
  grpc::CompletionQueue cq;
  std::vector<double> micros;
  micros.reserve(calls);
  for (int i = 0; i < kWarmUpCalls + calls; ++i) {
    const auto start = std::chrono::steady_clock::now();
    const grpc::Status status = Check(stub, cq);
    const double took = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start).count();
    if (!status.ok()) {
      return absl::UnavailableError(
          absl::StrCat("grpc.health.v1.Health/Check on ", target, ": ", status.error_message()));
    }
    if (i >= kWarmUpCalls) micros.push_back(took);
  }
  cq.Shutdown();
  void* tag = nullptr;
  bool ok = false;
  while (cq.Next(&tag, &ok)) {
  }
  TransportFloor floor;
  floor.calls = calls;
  floor.p50_us = Quantile(micros, 0.5);
  floor.p99_us = Quantile(micros, 0.99);
  return floor;
}

}  // namespace nupmpc::loadtest
