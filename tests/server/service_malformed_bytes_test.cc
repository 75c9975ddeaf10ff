// Request bytes that are not a valid message of the method's type get INVALID_ARGUMENT with
// a message naming the expected type (gRPC's generated code would answer UNIMPLEMENTED with
// no message), and the server keeps serving.
#include <string>

#include "gmock/gmock.h"
#include "grpcpp/generic/generic_stub.h"
#include "tests/server/service_fixture.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;

grpc::Status CallWithBytes(const std::string& target, const std::string& method, const std::string& bytes) {
  grpc::GenericStub stub(grpc::CreateChannel(target, grpc::InsecureChannelCredentials()));
  grpc::CompletionQueue queue;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  grpc::Slice slice(bytes);
  const grpc::ByteBuffer request(&slice, 1);
  std::unique_ptr<grpc::GenericClientAsyncResponseReader> call =
      stub.PrepareUnaryCall(&context, "/nupmpc.v1.MpcService/" + method, request, &queue);
  call->StartCall();
  grpc::ByteBuffer response;
  grpc::Status status;
  call->Finish(&response, &status, reinterpret_cast<void*>(1));
  void* tag = nullptr;
  bool ok = false;
  EXPECT_TRUE(queue.Next(&tag, &ok));
  queue.Shutdown();
  while (queue.Next(&tag, &ok)) {
  }
  return status;
}

// Opens a Control stream, sends `bytes` as its first message and returns the status the
// stream ends with.
grpc::Status ControlWithBytes(const std::string& target, const std::string& bytes) {
  grpc::GenericStub stub(grpc::CreateChannel(target, grpc::InsecureChannelCredentials()));
  grpc::CompletionQueue queue;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> stream =
      stub.PrepareCall(&context, "/nupmpc.v1.MpcService/Control", &queue);
  void* tag = nullptr;
  bool ok = false;
  const auto next = [&] { EXPECT_TRUE(queue.Next(&tag, &ok)); };
  stream->StartCall(reinterpret_cast<void*>(1));
  next();
  grpc::Slice slice(bytes);
  stream->Write(grpc::ByteBuffer(&slice, 1), reinterpret_cast<void*>(2));
  next();
  grpc::ByteBuffer answer;
  stream->Read(&answer, reinterpret_cast<void*>(3));
  next();
  EXPECT_FALSE(ok) << "the stream answered a message it could not parse";
  grpc::Status status;
  stream->Finish(&status, reinterpret_cast<void*>(4));
  next();
  queue.Shutdown();
  while (queue.Next(&tag, &ok)) {
  }
  return status;
}

class ServiceMalformedBytesTest : public ServiceTest {};

TEST_F(ServiceMalformedBytesTest, AControlStreamWhoseFirstMessageDoesNotParseEndsWithInvalidArgument) {
  const grpc::Status status = ControlWithBytes(target_, "\x0a\x02\xc3\x28");  // session_id = 0xC3 0x28
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
  EXPECT_THAT(status.error_message(), HasSubstr("nupmpc.v1.ControlRequest"));
  EXPECT_TRUE(client_->GetServerInfo().ok());
}

TEST_F(ServiceMalformedBytesTest, UnparseableRequestsAreInvalidArgumentWithAMessage) {
  std::string random_bytes;
  for (int i = 0; i < 4096; ++i) random_bytes.push_back(static_cast<char>((i * 7919 + 13) % 251));
  const std::string nested_groups(100000, '\x0b');       // field 1, start group, 100k deep
  const std::string invalid_utf8_id = "\x0a\x02\xc3\x28";  // session_id = 0xC3 0x28
  struct Case {
    const char* method;
    std::string bytes;
    const char* type;
  };
  const Case cases[] = {
      {"CreateSession", random_bytes, "nupmpc.v1.CreateSessionRequest"},
      {"SolveOnce", nested_groups, "nupmpc.v1.SolveOnceRequest"},
      {"CloseSession", invalid_utf8_id, "nupmpc.v1.CloseSessionRequest"},
      {"Solve", invalid_utf8_id, "nupmpc.v1.SolveRequest"},
      {"GetSession", random_bytes, "nupmpc.v1.GetSessionRequest"},
      {"FitGpModel", nested_groups, "nupmpc.v1.FitGpModelRequest"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.method);
    const grpc::Status status = CallWithBytes(target_, c.method, c.bytes);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
    EXPECT_THAT(status.error_message(), HasSubstr(c.type));
  }
  // Valid bytes still work through the same path.
  v1::GetServerInfoRequest empty;
  EXPECT_TRUE(CallWithBytes(target_, "GetServerInfo", empty.SerializeAsString()).ok());
  auto info = client_->GetServerInfo();
  ASSERT_TRUE(info.ok());
  EXPECT_GE(info->errors_by_code().at("INVALID_ARGUMENT"), 6u);
}

}  // namespace
}  // namespace nupmpc::testing
