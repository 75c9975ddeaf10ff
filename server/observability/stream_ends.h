#ifndef NUPMPC_SERVER_OBSERVABILITY_STREAM_ENDS_H_
#define NUPMPC_SERVER_OBSERVABILITY_STREAM_ENDS_H_

// Why Control streams ended, counted for /metrics (nupmpc_control_stream_ends_total) and
// named in the session's log line.

#include <array>
#include <atomic>
#include <cstdint>

namespace nupmpc::server {

enum class StreamEnd {
  kClientClosed,  // the client half-closed: the normal end
  kClientGone,    // cancelled while the client was active: it cancelled, or its connection was reset
  kKeepalive,     // cancelled after the client had been silent past the keepalive timeout: a partition,
                  // a frozen client or host, found by the server's keepalive pings
  kServerEnded,   // the server ended it with an error (refused attach, first-message timeout, token
                  // revoked, queue full, shutdown)
};
inline constexpr int kStreamEndCount = 4;

inline const char* StreamEndName(StreamEnd end) {
  switch (end) {
    case StreamEnd::kClientClosed:
      return "client_closed";
    case StreamEnd::kClientGone:
      return "client_gone";
    case StreamEnd::kKeepalive:
      return "keepalive";
    case StreamEnd::kServerEnded:
      return "server_ended";
  }
  return "unknown";
}

class StreamEnds {
 public:
  void Record(StreamEnd end) { counts_[static_cast<int>(end)].fetch_add(1, std::memory_order_relaxed); }
  std::uint64_t count(StreamEnd end) const { return counts_[static_cast<int>(end)].load(std::memory_order_relaxed); }

 private:
  std::array<std::atomic<std::uint64_t>, kStreamEndCount> counts_{};
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_OBSERVABILITY_STREAM_ENDS_H_
