// The operators' HTTP listener on a real socket, with small limits so every bound is
// reached in a fraction of a second: slow heads time out with 408, a full listener evicts
// its oldest connection, bodies are refused unread, and a well-formed request is answered
// while all of that goes on.
#include "server/http/http_listener.h"

#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "gtest/gtest.h"
#include "tests/util/raw_http.h"

namespace nupmpc::server {
namespace {

using std::chrono::milliseconds;
using namespace std::string_literals;
using ::nupmpc::testing::ClosedByPeerWithin;
using ::nupmpc::testing::ConnectLoopback;
using ::nupmpc::testing::RawRequest;
using ::nupmpc::testing::RawResponse;
using ::nupmpc::testing::ReadResponse;
using ::nupmpc::testing::SendAll;

// Generous against a loaded machine: the mechanisms are asserted, not their speed.
constexpr milliseconds kAnswerTimeout{10000};

class HttpListenerTest : public ::testing::Test {
 protected:
  void Start(HttpListenerLimits limits) {
    auto started = HttpListener::Start(
        "127.0.0.1", 0,
        [this](const HttpRequestHead& request) {
          ++handled_;
          if (request.path == "/throw") throw std::runtime_error("the handler failed");
          HttpResponse response;
          response.body = "path " + request.path + "\n";
          return response;
        },
        limits);
    ASSERT_TRUE(started.ok()) << started.status();
    listener_ = *std::move(started);
  }
  std::optional<RawResponse> Send(const std::string& bytes) {
    const int fd = ConnectLoopback(listener_->port());
    if (fd < 0 || !SendAll(fd, bytes)) return std::nullopt;
    std::optional<RawResponse> response = ReadResponse(fd, kAnswerTimeout);
    close(fd);
    return response;
  }
  std::atomic<int> handled_{0};
  std::unique_ptr<HttpListener> listener_;
};

TEST_F(HttpListenerTest, AnswersGetAndHeadWithLengthAndClose) {
  Start({});
  const std::optional<RawResponse> get = RawRequest(listener_->port(), "GET", "/x?y=1", kAnswerTimeout);
  ASSERT_TRUE(get.has_value());
  EXPECT_EQ(get->status, 200);
  EXPECT_EQ(get->body, "path /x\n");
  EXPECT_NE(get->head.find("Content-Length: 8\r\n"), std::string::npos) << get->head;
  EXPECT_NE(get->head.find("Connection: close"), std::string::npos) << get->head;

  const std::optional<RawResponse> head = RawRequest(listener_->port(), "HEAD", "/x", kAnswerTimeout);
  ASSERT_TRUE(head.has_value());
  EXPECT_EQ(head->status, 200);
  EXPECT_EQ(head->body, "");
  EXPECT_NE(head->head.find("Content-Length: 8\r\n"), std::string::npos) << head->head;
}

TEST_F(HttpListenerTest, AHandlerThatThrowsGets500AndTheListenerGoesOn) {
  Start({});
  const std::optional<RawResponse> failed = RawRequest(listener_->port(), "GET", "/throw", kAnswerTimeout);
  ASSERT_TRUE(failed.has_value());
  EXPECT_EQ(failed->status, 500);
  EXPECT_EQ(failed->body, "could not answer: the handler failed\n");
  const std::optional<RawResponse> next = RawRequest(listener_->port(), "GET", "/next", kAnswerTimeout);
  ASSERT_TRUE(next.has_value());
  EXPECT_EQ(next->status, 200);
}

TEST_F(HttpListenerTest, AnswersARequestWhoseSenderHalfClosedAfterIt) {
  Start({});
  const int fd = ConnectLoopback(listener_->port());
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(SendAll(fd, "GET /half HTTP/1.1\r\n\r\n"));
  shutdown(fd, SHUT_WR);
  const std::optional<RawResponse> response = ReadResponse(fd, kAnswerTimeout);
  close(fd);
  ASSERT_TRUE(response.has_value());
  EXPECT_EQ(response->body, "path /half\n");
}

TEST_F(HttpListenerTest, RefusesOtherMethodsBodiesAndOversizedHeadsWithoutCallingTheHandler) {
  HttpListenerLimits limits;
  limits.head.max_header_fields = 10;
  Start(limits);
  const std::optional<RawResponse> post = Send("POST /x HTTP/1.1\r\n\r\n");
  ASSERT_TRUE(post.has_value());
  EXPECT_EQ(post->status, 405);
  EXPECT_NE(post->head.find("Allow: GET, HEAD"), std::string::npos);

  // A body is refused from its announcement, before (and without) reading it.
  const std::optional<RawResponse> body = Send("GET /x HTTP/1.1\r\nContent-Length: 1000000000\r\n\r\nabc");
  ASSERT_TRUE(body.has_value());
  EXPECT_EQ(body->status, 413);

  std::string many_fields = "GET /x HTTP/1.1\r\n";
  // Within what the listener reads and drops after answering (linger_bytes), so it sees
  // this client's end of the request and the 431 is not lost to a reset.
  for (int i = 0; i < 2000; ++i) many_fields += "X-" + std::to_string(i) + ": v\r\n";
  many_fields += "\r\n";
  ASSERT_LT(many_fields.size(), limits.linger_bytes);
  const std::optional<RawResponse> fields = Send(many_fields);
  ASSERT_TRUE(fields.has_value());
  EXPECT_EQ(fields->status, 431);
  EXPECT_EQ(fields->body, "more than 10 header fields\n");

  // The start of a TLS ClientHello, NUL bytes included, as a client with the wrong scheme sends.
  const std::optional<RawResponse> garbage = Send("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\r\n\r\n"s);
  ASSERT_TRUE(garbage.has_value());
  EXPECT_EQ(garbage->status, 400);
  EXPECT_EQ(handled_.load(), 0);

  const std::optional<RawResponse> fine = RawRequest(listener_->port(), "GET", "/after", kAnswerTimeout);
  ASSERT_TRUE(fine.has_value());
  EXPECT_EQ(fine->status, 200);
}

TEST_F(HttpListenerTest, AHeadNotCompleteByTheReadDeadlineGets408AndIsClosed) {
  HttpListenerLimits limits;
  limits.read_deadline = milliseconds(300);
  Start(limits);
  const int fd = ConnectLoopback(listener_->port());
  ASSERT_GE(fd, 0);
  // A byte well inside the deadline does not extend it: the deadline runs from the accept.
  ASSERT_TRUE(SendAll(fd, "GET /slow HTTP/1.1\r\n"));
  std::this_thread::sleep_for(milliseconds(150));
  ASSERT_TRUE(SendAll(fd, "X"));
  const std::optional<RawResponse> response = ReadResponse(fd, kAnswerTimeout);
  close(fd);
  ASSERT_TRUE(response.has_value()) << "no 408 before the listener closed";
  EXPECT_EQ(response->status, 408);
  EXPECT_EQ(listener_->counts().timed_out, 1u);
  EXPECT_EQ(handled_.load(), 0);
}

// Slow connections beyond max_connections cost their oldest, not the newcomer: a request
// arriving while the listener is full of half-sent heads is answered at once, long before
// any of them reaches its read deadline.
TEST_F(HttpListenerTest, AFullListenerEvictsItsOldestSlowConnectionForANewOne) {
  HttpListenerLimits limits;
  limits.max_connections = 16;
  limits.read_deadline = milliseconds(60000);
  Start(limits);
  std::vector<int> slow;
  for (int i = 0; i < 40; ++i) {
    const int fd = ConnectLoopback(listener_->port());
    ASSERT_GE(fd, 0);
    ASSERT_TRUE(SendAll(fd, "GET /slow HTTP/1.1\r\nX-Slow: "));
    slow.push_back(fd);
  }
  // The first 24 were evicted to admit the next ones (and the listener is full again).
  for (int i = 0; i < 24; ++i) EXPECT_TRUE(ClosedByPeerWithin(slow[i], kAnswerTimeout)) << i;
  const auto started = std::chrono::steady_clock::now();
  const std::optional<RawResponse> fine = RawRequest(listener_->port(), "GET", "/fine", kAnswerTimeout);
  ASSERT_TRUE(fine.has_value());
  EXPECT_EQ(fine->status, 200);
  // Far less than the 60 s read deadline: nothing had to time out to make room.
  EXPECT_LT(std::chrono::steady_clock::now() - started, std::chrono::seconds(30));
  EXPECT_GE(listener_->counts().evicted, 25u);
  EXPECT_EQ(listener_->counts().timed_out, 0u);
  // The newest 15 slow connections are still open (the 16th slot went to /fine, then to
  // nobody, since the request evicted the oldest remaining one).
  int still_open = 0;
  for (int i = 24; i < 40; ++i) still_open += ClosedByPeerWithin(slow[i], milliseconds(50)) ? 0 : 1;
  EXPECT_EQ(still_open, 15);
  for (const int fd : slow) close(fd);
}

TEST_F(HttpListenerTest, StopsWithConnectionsOpen) {
  Start({});
  std::vector<int> open;
  for (int i = 0; i < 8; ++i) {
    open.push_back(ConnectLoopback(listener_->port()));
    SendAll(open.back(), "GET /");
  }
  listener_.reset();  // joins: a hang here fails the test by its timeout
  for (const int fd : open) {
    EXPECT_TRUE(ClosedByPeerWithin(fd, kAnswerTimeout));
    close(fd);
  }
}

}  // namespace
}  // namespace nupmpc::server
