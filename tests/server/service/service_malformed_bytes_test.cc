// Request bytes that are not a valid message of the method's type get INVALID_ARGUMENT with
// a message naming the expected type (gRPC's generated code would answer UNIMPLEMENTED with
// no message), and the server keeps serving.
#include <string>

#include "gmock/gmock.h"
#include "tests/server/hostile/hostile_catalogue.h"

namespace nupmpc::testing {
namespace {

using ::testing::HasSubstr;

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
  const std::string nested_groups(100000, '\x0b');         // field 1, start group, 100k deep
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
