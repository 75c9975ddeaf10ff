#include "server/http/http_listener.h"

#include <netdb.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <exception>

#include "absl/cleanup/cleanup.h"
#include "absl/strings/str_cat.h"

namespace nupmpc::server {
namespace {

constexpr int kMaxEventsPerWait = 64;
// How long accepting pauses when the process is out of file descriptors, so the listening
// socket (level-triggered and still readable) does not spin the thread.
constexpr std::chrono::milliseconds kAcceptPauseWhenOutOfDescriptors{100};

const char* ReasonPhrase(int status) {
  switch (status) {
    case 200:
      return "OK";
    case 400:
      return "Bad Request";
    case 404:
      return "Not Found";
    case 405:
      return "Method Not Allowed";
    case 408:
      return "Request Timeout";
    case 413:
      return "Content Too Large";
    case 431:
      return "Request Header Fields Too Large";
    case 500:
      return "Internal Server Error";
    case 503:
      return "Service Unavailable";
    default:
      return "Status";
  }
}

HttpResponse TextResponse(int status, std::string body) {
  HttpResponse response;
  response.status = status;
  response.body = std::move(body);
  return response;
}

std::string Serialize(const HttpResponse& response, bool head_only) {
  std::string out = absl::StrCat("HTTP/1.1 ", response.status, " ", ReasonPhrase(response.status),
                                 "\r\nContent-Type: ", response.content_type,
                                 "\r\nContent-Length: ", response.body.size(), "\r\nConnection: close\r\n");
  if (response.status == 405) out += "Allow: GET, HEAD\r\n";
  out += "\r\n";
  if (!head_only) out += response.body;
  return out;
}

absl::Status Unavailable(const std::string& host, int port, const std::string& what) {
  return absl::UnavailableError(absl::StrCat("could not listen on ", host, ":", port, ": ", what));
}

}  // namespace

absl::StatusOr<std::unique_ptr<HttpListener>> HttpListener::Start(const std::string& host, int port, Handler handler,
                                                                  HttpListenerLimits limits) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* resolved = nullptr;
  const std::string port_text = std::to_string(port);
  if (const int error = getaddrinfo(host.c_str(), port_text.c_str(), &hints, &resolved); error != 0) {
    return Unavailable(host, port, gai_strerror(error));
  }
  absl::Cleanup free_resolved = [resolved] { freeaddrinfo(resolved); };

  std::unique_ptr<HttpListener> listener(new HttpListener(std::move(handler), limits));
  std::string last_error = "no address";
  // The first of the host's addresses that binds, in the resolver's order.
  for (const addrinfo* a = resolved; a != nullptr && listener->listen_fd_ < 0; a = a->ai_next) {
    const int fd = socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, a->ai_protocol);
    if (fd < 0) {
      last_error = std::strerror(errno);
      continue;
    }
    // SO_REUSEADDR lets a restart bind while the last run's connections are in TIME_WAIT;
    // never SO_REUSEPORT, with which a second server would share the port and answer some
    // scrapes with its own figures.
    const int yes = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    if (bind(fd, a->ai_addr, a->ai_addrlen) != 0 || listen(fd, SOMAXCONN) != 0) {
      last_error = std::strerror(errno);
      close(fd);
      continue;
    }
    listener->listen_fd_ = fd;
  }
  if (listener->listen_fd_ < 0) return Unavailable(host, port, last_error);

  sockaddr_storage bound{};
  socklen_t bound_size = sizeof bound;
  getsockname(listener->listen_fd_, reinterpret_cast<sockaddr*>(&bound), &bound_size);
  listener->port_ = ntohs(bound.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&bound)->sin6_port
                                                      : reinterpret_cast<sockaddr_in*>(&bound)->sin_port);

  listener->epoll_fd_ = epoll_create1(EPOLL_CLOEXEC);
  listener->wake_fd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (listener->epoll_fd_ < 0 || listener->wake_fd_ < 0) return Unavailable(host, port, std::strerror(errno));
  listener->Watch(listener->listen_fd_, EPOLLIN, EPOLL_CTL_ADD);
  listener->Watch(listener->wake_fd_, EPOLLIN, EPOLL_CTL_ADD);
  listener->thread_ = std::thread([l = listener.get()] { l->Run(); });
  return listener;
}

HttpListener::~HttpListener() {
  if (thread_.joinable()) {
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t written = write(wake_fd_, &one, sizeof one);
    thread_.join();
  }
  for (const auto& [fd, connection] : connections_) close(fd);
  for (const int fd : {listen_fd_, epoll_fd_, wake_fd_}) {
    if (fd >= 0) close(fd);
  }
}

HttpListenerCounts HttpListener::counts() const {
  return {accepted_.load(), answered_.load(), timed_out_.load(), evicted_.load()};
}

void HttpListener::Watch(int fd, std::uint32_t events, int operation) const {
  epoll_event event{};
  event.events = events;
  event.data.fd = fd;
  epoll_ctl(epoll_fd_, operation, fd, &event);
}

void HttpListener::Run() {
  std::array<epoll_event, kMaxEventsPerWait> events{};
  Clock::time_point next_wake = Clock::time_point::max();
  while (true) {
    const int ready =
        epoll_wait(epoll_fd_, events.data(), kMaxEventsPerWait, MillisecondsUntil(next_wake, Clock::now()));
    for (int i = 0; i < ready; ++i) {
      const int fd = events[i].data.fd;
      if (fd == wake_fd_) return;
      if (fd == listen_fd_) {
        AcceptAll();
        continue;
      }
      // A connection closed earlier in this batch (its descriptor possibly reused by an
      // accept since) is looked up again, and a stale event on a new one finds nothing
      // to read yet: harmless.
      const auto it = connections_.find(fd);
      if (it == connections_.end()) continue;
      if (it->second.phase == Phase::kWriting) {
        OnWritable(fd, it->second);
      } else {
        OnReadable(fd, it->second);
      }
    }
    const Clock::time_point now = Clock::now();
    next_wake = CloseExpired(now);
    if (accept_paused_ && now >= accept_resume_at_) {
      accept_paused_ = false;
      Watch(listen_fd_, EPOLLIN, EPOLL_CTL_MOD);
    }
    if (accept_paused_) next_wake = std::min(next_wake, accept_resume_at_);
  }
}

int HttpListener::MillisecondsUntil(Clock::time_point next, Clock::time_point now) {
  if (next == Clock::time_point::max()) return -1;
  if (next <= now) return 0;
  // Rounded up, so a wake-up never comes just before the deadline it waits for.
  return static_cast<int>(std::chrono::ceil<std::chrono::milliseconds>(next - now).count());
}
void HttpListener::AcceptAll() {
  while (true) {
    const int fd = accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) {
      if (errno == EINTR || errno == ECONNABORTED) continue;
      if ((errno == EMFILE || errno == ENFILE) && EvictOldest()) continue;
      if (errno == EMFILE || errno == ENFILE || errno == ENOBUFS || errno == ENOMEM) {
        accept_paused_ = true;
        accept_resume_at_ = Clock::now() + kAcceptPauseWhenOutOfDescriptors;
        Watch(listen_fd_, 0, EPOLL_CTL_MOD);
      }
      return;  // EAGAIN: accepted everything waiting
    }
    if (static_cast<int>(connections_.size()) >= limits_.max_connections) EvictOldest();
    const Clock::time_point now = Clock::now();
    Connection& connection = connections_[fd];
    connection.accept_order = accepted_++;
    connection.deadline = now + limits_.read_deadline;
    Watch(fd, EPOLLIN | EPOLLRDHUP, EPOLL_CTL_ADD);
  }
}

bool HttpListener::EvictOldest() {
  auto oldest = connections_.end();
  for (auto it = connections_.begin(); it != connections_.end(); ++it) {
    const bool sending = it->second.phase == Phase::kWriting;
    const bool oldest_sending = oldest != connections_.end() && oldest->second.phase == Phase::kWriting;
    if (oldest == connections_.end() || (oldest_sending && !sending) ||
        (sending == oldest_sending && it->second.accept_order < oldest->second.accept_order)) {
      oldest = it;
    }
  }
  if (oldest == connections_.end()) return false;
  ++evicted_;
  Close(oldest->first);
  return true;
}

void HttpListener::OnReadable(int fd, Connection& connection) {
  if (connection.phase == Phase::kLingering) {
    Linger(fd, connection);
    return;
  }
  // Reads at most one byte past the head limit: enough to know it was exceeded.
  std::array<char, 4096> buffer{};
  bool peer_done = false;  // closed its sending side (a complete request is still answered) or failed
  while (connection.received.size() <= limits_.head.max_head_bytes) {
    const std::size_t room = limits_.head.max_head_bytes + 1 - connection.received.size();
    const ssize_t n = recv(fd, buffer.data(), std::min(room, buffer.size()), 0);
    if (n > 0) {
      connection.received.append(buffer.data(), static_cast<std::size_t>(n));
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
    peer_done = true;
    break;
  }
  const HeadParse parse = ParseRequestHead(connection.received, limits_.head);
  switch (parse.state) {
    case HeadParseState::kIncomplete:
      if (peer_done) Close(fd);
      return;
    case HeadParseState::kRefused:
      Answer(fd, connection, TextResponse(parse.status, parse.reason + "\n"), false);
      return;
    case HeadParseState::kComplete:
      break;
  }
  const HttpRequestHead& head = parse.head;
  const bool head_only = head.method == "HEAD";
  if (head.method != "GET" && !head_only) {
    Answer(fd, connection, TextResponse(405, "only GET and HEAD are served here\n"), false);
  } else if (head.announces_body) {
    Answer(fd, connection, TextResponse(413, "this endpoint takes no request body\n"), head_only);
  } else {
    Answer(fd, connection, Handle(head), head_only);
  }
}

HttpResponse HttpListener::Handle(const HttpRequestHead& head) const {
  // An exception out of the handler (out of memory while rendering /metrics) must not end
  // the listener's thread, and with it the process.
  try {
    return handler_(head);
  } catch (const std::exception& e) {
    return TextResponse(500, absl::StrCat("could not answer: ", e.what(), "\n"));
  }
}

void HttpListener::Answer(int fd, Connection& connection, const HttpResponse& response, bool head_only) {
  connection.phase = Phase::kWriting;
  connection.response = Serialize(response, head_only);
  connection.received.clear();
  connection.received.shrink_to_fit();
  connection.deadline = Clock::now() + limits_.write_deadline;
  Watch(fd, EPOLLOUT, EPOLL_CTL_MOD);
  OnWritable(fd, connection);
}

void HttpListener::OnWritable(int fd, Connection& connection) {
  while (connection.sent < connection.response.size()) {
    const ssize_t n = send(fd, connection.response.data() + connection.sent,
                           connection.response.size() - connection.sent, MSG_NOSIGNAL);
    if (n > 0) {
      connection.sent += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return;
    Close(fd);
    return;
  }
  ++answered_;
  // Half-close and read out what the peer still sends (a request body it had started, a
  // pipelined request) until it closes: closing with unread bytes would send a reset,
  // which can discard the response before the peer has read it.
  shutdown(fd, SHUT_WR);
  connection.phase = Phase::kLingering;
  connection.response.clear();
  connection.response.shrink_to_fit();
  connection.deadline = Clock::now() + limits_.linger_time;
  Watch(fd, EPOLLIN | EPOLLRDHUP, EPOLL_CTL_MOD);
  Linger(fd, connection);
}

void HttpListener::Linger(int fd, Connection& connection) {
  std::array<char, 4096> buffer{};
  while (connection.lingered <= limits_.linger_bytes) {
    const ssize_t n = recv(fd, buffer.data(), buffer.size(), 0);
    if (n > 0) {
      connection.lingered += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return;
    break;  // the peer closed (or reset): done
  }
  Close(fd);
}

HttpListener::Clock::time_point HttpListener::CloseExpired(Clock::time_point now) {
  Clock::time_point next = Clock::time_point::max();
  for (auto it = connections_.begin(); it != connections_.end();) {
    const int fd = it->first;
    Connection& connection = it->second;
    ++it;  // Answer and Close below may erase `connection`
    if (connection.deadline > now) {
      next = std::min(next, connection.deadline);
      continue;
    }
    if (connection.phase == Phase::kReadingHead) {
      ++timed_out_;
      Answer(fd, connection, TextResponse(408, "request head not complete in time\n"), false);
      // Answered at once, or now waiting on its write (or linger) deadline.
      if (const auto left = connections_.find(fd); left != connections_.end())
        next = std::min(next, left->second.deadline);
    } else {
      if (connection.phase == Phase::kWriting) ++timed_out_;
      Close(fd);
    }
  }
  return next;
}

void HttpListener::Close(int fd) {
  epoll_ctl(epoll_fd_, EPOLL_CTL_DEL, fd, nullptr);
  close(fd);
  connections_.erase(fd);
}

}  // namespace nupmpc::server
