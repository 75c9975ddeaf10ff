#ifndef NUPMPC_SERVER_RPC_RAW_MESSAGES_H_
#define NUPMPC_SERVER_RPC_RAW_MESSAGES_H_

// The service takes its messages as raw bytes and parses them itself: gRPC's generated code
// answers a request it cannot parse (random bytes, nesting deeper than protobuf's limit, a
// string field that is not UTF-8) with UNIMPLEMENTED and no message.

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "grpcpp/impl/codegen/proto_utils.h"
#include "grpcpp/support/byte_buffer.h"

namespace nupmpc::server {

// Parses `bytes` (consumed) into `out`; INVALID_ARGUMENT naming the expected type if they
// are not a valid message of it.
template <class Message>
absl::Status ParseRaw(grpc::ByteBuffer* bytes, Message* out) {
  if (grpc::SerializationTraits<Message>::Deserialize(bytes, out).ok()) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrCat("request: not a valid ", Message::descriptor()->full_name(),
                   " (malformed protobuf, nested deeper than protobuf's limit, or a string field that is not UTF-8)"));
}

// `message` serialized into `out`.
template <class Message>
absl::Status SerializeRaw(const Message& message, grpc::ByteBuffer* out) {
  bool own_buffer = false;
  if (grpc::SerializationTraits<Message>::Serialize(message, out, &own_buffer).ok()) return absl::OkStatus();
  return absl::InternalError(absl::StrCat("the ", Message::descriptor()->full_name(), " could not be serialized"));
}

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_RPC_RAW_MESSAGES_H_
