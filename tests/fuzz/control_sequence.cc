#include "tests/fuzz/control_sequence.h"

namespace nupmpc::fuzz {
namespace {

constexpr std::uint8_t kCancelAtEnd = 1;
constexpr std::uint8_t kLockStep = 2;

}  // namespace

ControlSequence DecodeControlSequence(const std::uint8_t* data, std::size_t size) {
  ControlSequence sequence;
  if (size == 0) return sequence;
  sequence.cancel_at_end = (data[0] & kCancelAtEnd) != 0;
  sequence.lock_step = (data[0] & kLockStep) != 0;
  std::size_t at = 1;
  while (at + 2 <= size && sequence.requests.size() < kMaxControlRequests) {
    const std::size_t length = data[at] | (static_cast<std::size_t>(data[at + 1]) << 8);
    at += 2;
    if (length > size - at) break;
    v1::ControlRequest request;
    if (request.ParseFromArray(data + at, static_cast<int>(length))) sequence.requests.push_back(std::move(request));
    at += length;
  }
  return sequence;
}

std::string EncodeControlSequence(const ControlSequence& sequence) {
  std::string bytes(
      1, static_cast<char>((sequence.cancel_at_end ? kCancelAtEnd : 0) | (sequence.lock_step ? kLockStep : 0)));
  for (const v1::ControlRequest& request : sequence.requests) {
    const std::string frame = request.SerializeAsString();
    if (frame.size() > 0xFFFF) continue;  // not representable; the seeds stay far below
    bytes.push_back(static_cast<char>(frame.size() & 0xFF));
    bytes.push_back(static_cast<char>(frame.size() >> 8));
    bytes += frame;
  }
  return bytes;
}

}  // namespace nupmpc::fuzz
