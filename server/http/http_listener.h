#ifndef NUPMPC_SERVER_HTTP_HTTP_LISTENER_H_
#define NUPMPC_SERVER_HTTP_HTTP_LISTENER_H_

// A small HTTP/1.x listener for GET-only endpoints on a port anyone on the network may
// reach (the operators' /metrics, /healthz, /readyz). One thread, one epoll set,
// non-blocking sockets: a slow or hostile peer costs a few kilobytes and never a thread,
// and every connection has a deadline from the moment it is accepted. See server/README.md
// for why this is not cpp-httplib.
//
// Bounds, each a field of HttpListenerLimits:
// - a request head (request line and header fields) of at most max_head_bytes and
//   max_header_fields, complete within read_deadline of the accept: otherwise 431 or 408;
// - no request body: a request announcing one gets 413 and its body is not read;
// - methods GET and HEAD (405 otherwise); one request per connection (Connection: close);
// - the response sent within write_deadline, then at most linger_bytes of whatever the
//   peer still sends are read and dropped for at most linger_time, so the peer reads the
//   response before the connection closes instead of a reset;
// - at most max_connections open: a new connection closes the oldest one that is not
//   sending a response (or the oldest of all when every one is).

#include <sys/types.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <thread>

#include "absl/status/statusor.h"
#include "server/http/http_request_head.h"

namespace nupmpc::server {

struct HttpResponse {
  int status = 200;
  std::string content_type = "text/plain; charset=utf-8";
  std::string body;
};

struct HttpListenerLimits {
  HttpHeadLimits head;
  std::chrono::milliseconds read_deadline{5000};
  std::chrono::milliseconds write_deadline{5000};
  std::chrono::milliseconds linger_time{1000};
  std::size_t linger_bytes = 64 * 1024;
  int max_connections = 512;
};

// What the listener did, for tests and operators.
struct HttpListenerCounts {
  std::uint64_t accepted = 0;
  std::uint64_t answered = 0;   // responses sent in full, errors included
  std::uint64_t timed_out = 0;  // closed at a read or write deadline
  std::uint64_t evicted = 0;    // closed to admit a newer connection
};

class HttpListener {
 public:
  // Called on the listener's thread for GET and HEAD requests (the listener drops the body
  // of a HEAD answer); it must not block.
  using Handler = std::function<HttpResponse(const HttpRequestHead&)>;

  // Binds the first of `host`'s addresses that binds (a name or a numeric address; port 0
  // picks a free one) and starts serving. UNAVAILABLE with the system's reason when it
  // cannot listen.
  static absl::StatusOr<std::unique_ptr<HttpListener>> Start(const std::string& host, int port, Handler handler,
                                                             HttpListenerLimits limits = {});
  ~HttpListener();  // stops, closes every connection and joins
  HttpListener(const HttpListener&) = delete;
  HttpListener& operator=(const HttpListener&) = delete;

  int port() const { return port_; }
  HttpListenerCounts counts() const;

 private:
  enum class Phase { kReadingHead, kWriting, kLingering };
  struct Connection {
    Phase phase = Phase::kReadingHead;
    std::uint64_t accept_order = 0;  // which is oldest, for eviction
    std::chrono::steady_clock::time_point deadline;
    std::string received;
    std::string response;
    std::size_t sent = 0;
    std::size_t lingered = 0;
  };
  using Clock = std::chrono::steady_clock;

  HttpListener(Handler handler, HttpListenerLimits limits) : handler_(std::move(handler)), limits_(limits) {}
  void Run();
  void AcceptAll();
  void OnReadable(int fd, Connection& connection);
  void OnWritable(int fd, Connection& connection);
  HttpResponse Handle(const HttpRequestHead& head) const;
  void Answer(int fd, Connection& connection, const HttpResponse& response, bool head_only);
  void Linger(int fd, Connection& connection);
  // Ends the connections whose deadline has passed; the earliest deadline of those left.
  Clock::time_point CloseExpired(Clock::time_point now);
  bool EvictOldest();
  void Close(int fd);
  // epoll_wait's timeout until `next` (-1: none).
  static int MillisecondsUntil(Clock::time_point next, Clock::time_point now);
  void Watch(int fd, std::uint32_t events, int operation) const;

  Handler handler_;
  HttpListenerLimits limits_;
  int listen_fd_ = -1;
  int epoll_fd_ = -1;
  int wake_fd_ = -1;  // an eventfd: written by the destructor to end Run()
  int port_ = 0;
  bool accept_paused_ = false;  // out of file descriptors: retried at the next wake-up
  Clock::time_point accept_resume_at_;
  std::map<int, Connection> connections_;  // by file descriptor
  std::atomic<std::uint64_t> accepted_{0}, answered_{0}, timed_out_{0}, evicted_{0};
  std::thread thread_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_HTTP_HTTP_LISTENER_H_
