#ifndef NUPMPC_SERVER_HTTP_HTTP_REQUEST_HEAD_H_
#define NUPMPC_SERVER_HTTP_HTTP_REQUEST_HEAD_H_

// The request head (request line and header fields) of an HTTP/1.x request, as the
// operators' endpoint needs it: method, path and whether a body follows. Parsing is a
// pure function of the bytes received so far, so the listener can call it after every
// read and the limits are tested without sockets.

#include <cstddef>
#include <string>

#include "absl/strings/string_view.h"

namespace nupmpc::server {

struct HttpHeadLimits {
  std::size_t max_head_bytes = 8 * 1024;  // request line + header fields + the empty line
  int max_header_fields = 64;
};

struct HttpRequestHead {
  std::string method;
  std::string path;             // the request target without its query string
  bool announces_body = false;  // Content-Length > 0 or any Transfer-Encoding
};

enum class HeadParseState {
  kIncomplete,  // no empty line yet and no limit exceeded: read more
  kComplete,
  kRefused,  // malformed or over a limit: answer `status` and close
};

struct HeadParse {
  HeadParseState state = HeadParseState::kIncomplete;
  HttpRequestHead head;  // set when kComplete
  int status = 0;        // set when kRefused: 400 or 431
  std::string reason;    // set when kRefused, for the response body
};

// Looks at everything received on the connection so far (bytes after the head, a body or
// a pipelined request, are ignored). Header lines may end in CRLF or a bare LF.
HeadParse ParseRequestHead(absl::string_view received, const HttpHeadLimits& limits);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_HTTP_HTTP_REQUEST_HEAD_H_
