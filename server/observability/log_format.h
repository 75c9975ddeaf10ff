#ifndef NUPMPC_SERVER_OBSERVABILITY_LOG_FORMAT_H_
#define NUPMPC_SERVER_OBSERVABILITY_LOG_FORMAT_H_

// --log_format: how the server's log lines look.
//   text: [2026-12-03 13:47:34.289] [info] session 3f… created … session=3f… principal=alice
//   json: {"time":"2026-12-03T13:47:34.289123Z","level":"info","msg":"…","session":"3f…","principal":"alice"}
// one object per line, UTC, for log collectors (Loki, Elasticsearch, journald's JSON).

#include <memory>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "spdlog/formatter.h"

namespace nupmpc::server {

// The formatter of `format` ("text" or "json"); INVALID_ARGUMENT naming --log_format for
// anything else.
absl::StatusOr<std::unique_ptr<spdlog::formatter>> MakeLogFormatter(absl::string_view format);

// Sets the default logger's formatter and level (level names as spdlog's: trace … off).
absl::Status ConfigureLogging(absl::string_view format, absl::string_view level);

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_OBSERVABILITY_LOG_FORMAT_H_
