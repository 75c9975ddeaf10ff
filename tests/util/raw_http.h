#ifndef NUPMPC_TESTS_UTIL_RAW_HTTP_H_
#define NUPMPC_TESTS_UTIL_RAW_HTTP_H_

// HTTP over plain sockets, for tests that must send what no well-behaved client library
// sends (a request head one byte at a time, ten thousand header fields, a body nobody
// asked for) and see exactly what the server answers.

#include <chrono>
#include <optional>
#include <string>

namespace nupmpc::testing {

// A blocking TCP connection to 127.0.0.1:port; -1 when it cannot connect.
int ConnectLoopback(int port);

// Sends all of `bytes`; false when the peer closed or reset the connection first.
bool SendAll(int fd, const std::string& bytes);

struct RawResponse {
  int status = 0;
  std::string head;  // status line and header fields
  std::string body;
};

// Reads until the peer closes (every answer of the servers tested here ends its
// connection) or `timeout` passes; nullopt when no status line arrived in time.
std::optional<RawResponse> ReadResponse(int fd, std::chrono::milliseconds timeout);

// One request on a new connection: "METHOD path" with a Host field and nothing else.
std::optional<RawResponse> RawRequest(int port, const std::string& method, const std::string& path,
                                      std::chrono::milliseconds timeout);

// Whether the peer has closed `fd` (a read returns end-of-file or a reset) within `timeout`;
// any bytes that arrive first are read and dropped.
bool ClosedByPeerWithin(int fd, std::chrono::milliseconds timeout);

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_RAW_HTTP_H_
