// The operators' endpoint's request parser, without sockets: what a complete head yields,
// when it waits for more, and which heads it refuses with which status.
#include "server/http/http_request_head.h"

#include <string>

#include "gtest/gtest.h"

namespace nupmpc::server {
namespace {

TEST(HttpRequestHead, CompleteGetYieldsMethodAndPathWithoutQuery) {
  const HeadParse parse = ParseRequestHead("GET /metrics?name[]=x HTTP/1.1\r\nHost: a\r\nAccept: */*\r\n\r\n", {});
  ASSERT_EQ(parse.state, HeadParseState::kComplete);
  EXPECT_EQ(parse.head.method, "GET");
  EXPECT_EQ(parse.head.path, "/metrics");
  EXPECT_FALSE(parse.head.announces_body);
}

TEST(HttpRequestHead, BareLineFeedsAndLeadingEmptyLinesAreAccepted) {
  const HeadParse parse = ParseRequestHead("\r\n\nHEAD /healthz HTTP/1.0\nHost: a\n\n", {});
  ASSERT_EQ(parse.state, HeadParseState::kComplete);
  EXPECT_EQ(parse.head.method, "HEAD");
  EXPECT_EQ(parse.head.path, "/healthz");
}

TEST(HttpRequestHead, WaitsForTheEmptyLine) {
  const std::string head = "GET /healthz HTTP/1.1\r\nHost: a\r\n\r\n";
  for (std::size_t size = 0; size < head.size(); ++size) {
    EXPECT_EQ(ParseRequestHead(head.substr(0, size), {}).state, HeadParseState::kIncomplete) << size;
  }
  EXPECT_EQ(ParseRequestHead(head, {}).state, HeadParseState::kComplete);
}

TEST(HttpRequestHead, BytesAfterTheHeadAreNotLookedAt) {
  const HeadParse parse = ParseRequestHead("GET / HTTP/1.1\r\n\r\n\x01\x02 not a request", {});
  EXPECT_EQ(parse.state, HeadParseState::kComplete);
}

TEST(HttpRequestHead, AnnouncedBodiesAreSeen) {
  EXPECT_TRUE(ParseRequestHead("POST / HTTP/1.1\r\nContent-Length: 268435456\r\n\r\n", {}).head.announces_body);
  EXPECT_TRUE(ParseRequestHead("GET / HTTP/1.1\r\ntransfer-encoding: chunked\r\n\r\n", {}).head.announces_body);
  EXPECT_FALSE(ParseRequestHead("GET / HTTP/1.1\r\nContent-Length: 0\r\n\r\n", {}).head.announces_body);
}

TEST(HttpRequestHead, MalformedHeadsAreRefusedWith400) {
  for (const char* head :
       {"GET /metrics\r\n\r\n", "GET metrics HTTP/1.1\r\n\r\n", "GET  /metrics HTTP/1.1\r\n\r\n",
        "GET /metrics SPDY/3\r\n\r\n", "GET / HTTP/1.1\r\nno colon here\r\n\r\n",
        "GET / HTTP/1.1\r\nContent-Length : 5\r\n\r\n", "GET / HTTP/1.1\r\n: empty name\r\n\r\n",
        "GET / HTTP/1.1\r\nContent-Length: -1\r\n\r\n", "GET / HTTP/1.1\r\nContent-Length: 1x\r\n\r\n"}) {
    const HeadParse parse = ParseRequestHead(head, {});
    EXPECT_EQ(parse.state, HeadParseState::kRefused) << head;
    EXPECT_EQ(parse.status, 400) << head;
  }
}

TEST(HttpRequestHead, TooManyFieldsAreRefusedWith431BeforeTheHeadEnds) {
  HttpHeadLimits limits;
  limits.max_header_fields = 3;
  std::string head = "GET / HTTP/1.1\r\n";
  for (int i = 0; i < 3; ++i) head += "X-A: b\r\n";
  EXPECT_EQ(ParseRequestHead(head, limits).state, HeadParseState::kIncomplete);
  head += "X-A: b\r\n";  // the fourth field: refused without waiting for the end of the head
  const HeadParse parse = ParseRequestHead(head, limits);
  EXPECT_EQ(parse.state, HeadParseState::kRefused);
  EXPECT_EQ(parse.status, 431);
  EXPECT_EQ(parse.reason, "more than 3 header fields");
}

TEST(HttpRequestHead, AHeadLongerThanTheLimitIsRefusedWith431WithOrWithoutALineEnd) {
  HttpHeadLimits limits;
  limits.max_head_bytes = 64;
  const std::string long_line = "GET /" + std::string(100, 'a');
  EXPECT_EQ(ParseRequestHead(long_line.substr(0, 63), limits).state, HeadParseState::kIncomplete);
  for (const std::string& head : {long_line, long_line + " HTTP/1.1\r\n\r\n"}) {
    const HeadParse parse = ParseRequestHead(head, limits);
    EXPECT_EQ(parse.state, HeadParseState::kRefused);
    EXPECT_EQ(parse.status, 431);
    EXPECT_EQ(parse.reason, "request head larger than 64 bytes");
  }
  // Exactly at the limit is accepted.
  std::string fits = "GET / HTTP/1.1\r\nX: ";
  fits += std::string(64 - fits.size() - 4, 'b') + "\r\n\r\n";
  ASSERT_EQ(fits.size(), 64u);
  EXPECT_EQ(ParseRequestHead(fits, limits).state, HeadParseState::kComplete);
}

}  // namespace
}  // namespace nupmpc::server
