#include "server/http/http_request_head.h"

#include <cstdint>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace nupmpc::server {
namespace {

HeadParse Refuse(int status, std::string reason) {
  HeadParse parse;
  parse.state = HeadParseState::kRefused;
  parse.status = status;
  parse.reason = std::move(reason);
  return parse;
}

// RFC 9112 section 3: method SP request-target SP HTTP-version. Only the origin form
// ("/path?query") names something this endpoint serves.
bool ParseRequestLine(absl::string_view line, HttpRequestHead& head) {
  const std::vector<absl::string_view> parts = absl::StrSplit(line, ' ');
  if (parts.size() != 3 || parts[0].empty() || !absl::StartsWith(parts[2], "HTTP/1.")) return false;
  const absl::string_view target = parts[1];
  if (target.empty() || target.front() != '/') return false;
  head.method = std::string(parts[0]);
  head.path = std::string(target.substr(0, target.find('?')));
  return true;
}

// A field line is `name ":" value`, the name without whitespace (RFC 9112 section 5.1
// requires refusing whitespace before the colon: it is a request-smuggling vector).
bool ApplyFieldLine(absl::string_view line, HttpRequestHead& head) {
  const std::size_t colon = line.find(':');
  if (colon == 0 || colon == absl::string_view::npos) return false;
  const absl::string_view name = line.substr(0, colon);
  for (const char c : name) {
    if (absl::ascii_isspace(static_cast<unsigned char>(c)) || absl::ascii_iscntrl(static_cast<unsigned char>(c))) {
      return false;
    }
  }
  const absl::string_view value = absl::StripAsciiWhitespace(line.substr(colon + 1));
  if (absl::EqualsIgnoreCase(name, "content-length")) {
    std::uint64_t length = 0;
    if (!absl::SimpleAtoi(value, &length)) return false;
    if (length > 0) head.announces_body = true;
  } else if (absl::EqualsIgnoreCase(name, "transfer-encoding")) {
    head.announces_body = true;
  }
  return true;
}

}  // namespace

HeadParse ParseRequestHead(absl::string_view received, const HttpHeadLimits& limits) {
  // Called after every read of an unfinished head: the refusal's text is built only when needed.
  const auto too_large = [&limits] {
    return Refuse(431, absl::StrCat("request head larger than ", limits.max_head_bytes, " bytes"));
  };
  HeadParse parse;
  bool have_request_line = false;
  int fields = 0;
  std::size_t line_start = 0;
  while (true) {
    const std::size_t newline = received.find('\n', line_start);
    if (newline == absl::string_view::npos) {
      if (received.size() >= limits.max_head_bytes) return too_large();
      return parse;  // kIncomplete
    }
    if (newline + 1 > limits.max_head_bytes) return too_large();
    absl::string_view line = received.substr(line_start, newline - line_start);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    line_start = newline + 1;

    if (!have_request_line) {
      if (line.empty()) continue;  // RFC 9112 section 2.2: empty lines before the request line are ignored
      if (!ParseRequestLine(line, parse.head)) return Refuse(400, "malformed request line");
      have_request_line = true;
      continue;
    }
    if (line.empty()) {
      parse.state = HeadParseState::kComplete;
      return parse;
    }
    if (++fields > limits.max_header_fields) {
      return Refuse(431, absl::StrCat("more than ", limits.max_header_fields, " header fields"));
    }
    if (!ApplyFieldLine(line, parse.head)) return Refuse(400, "malformed header field");
  }
}

}  // namespace nupmpc::server
