#ifndef NUPMPC_FUZZ_CONTROL_SEQUENCE_H_
#define NUPMPC_FUZZ_CONTROL_SEQUENCE_H_

// The input of control_stream_fuzzer: how a client drives one Control stream. Bytes: one
// byte of flags, then frames of a 2-byte little-endian length and that many bytes of a
// serialized ControlRequest. Length-prefixed frames rather than one wrapping message so
// that libFuzzer's byte mutations insert, drop and reorder whole requests.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::fuzz {

struct ControlSequence {
  // Cancel the call after the last request instead of half-closing it (a client that goes
  // away with steps in flight).
  bool cancel_at_end = false;
  // Read one answer after each request (a lock-step client) instead of all at the end.
  bool lock_step = false;
  std::vector<v1::ControlRequest> requests;  // frames that do not parse are left out
};

// At most this many requests are sent: fewer than the answers a stream queues for a client
// that is not reading (ServerOptions::max_stream_answers), so the sending side never blocks.
inline constexpr std::size_t kMaxControlRequests = 12;

ControlSequence DecodeControlSequence(const std::uint8_t* data, std::size_t size);
std::string EncodeControlSequence(const ControlSequence& sequence);

}  // namespace nupmpc::fuzz

#endif  // NUPMPC_FUZZ_CONTROL_SEQUENCE_H_
