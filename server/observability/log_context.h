#ifndef NUPMPC_SERVER_OBSERVABILITY_LOG_CONTEXT_H_
#define NUPMPC_SERVER_OBSERVABILITY_LOG_CONTEXT_H_

// The session and principal a log line is about. A LogContext in scope makes every line
// this thread logs meanwhile carry them (as `session=… principal=…` in text, as fields in
// JSON: server/observability/log_format.h); spdlog's default logger formats on the calling thread.

#include "absl/strings/string_view.h"

namespace nupmpc::server {

class LogContext {
 public:
  // The views must outlive the scope. An empty principal is left out.
  LogContext(absl::string_view session, absl::string_view principal);
  ~LogContext();
  LogContext(const LogContext&) = delete;
  LogContext& operator=(const LogContext&) = delete;

  // The innermost context of this thread (null: none).
  static const LogContext* Current();
  absl::string_view session() const { return session_; }
  absl::string_view principal() const { return principal_; }

 private:
  absl::string_view session_;
  absl::string_view principal_;
  const LogContext* outer_;
};

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_OBSERVABILITY_LOG_CONTEXT_H_
