#include "server/observability/log_context.h"

namespace nupmpc::server {
namespace {
thread_local const LogContext* current = nullptr;
}  // namespace

LogContext::LogContext(absl::string_view session, absl::string_view principal)
    : session_(session), principal_(principal), outer_(current) {
  current = this;
}

LogContext::~LogContext() { current = outer_; }

const LogContext* LogContext::Current() { return current; }

}  // namespace nupmpc::server
