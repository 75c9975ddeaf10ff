#include "server/observability/log_format.h"

#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "grpc/support/log.h"
#include "server/observability/log_context.h"
#include "spdlog/pattern_formatter.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {
namespace {

// JSON string contents (RFC 8259: quote, backslash and control characters escaped).
void AppendJsonEscaped(absl::string_view text, spdlog::memory_buf_t& out) {
  for (const char c : text) {
    switch (c) {
      case '"':
        out.append(absl::string_view("\\\""));
        break;
      case '\\':
        out.append(absl::string_view("\\\\"));
        break;
      case '\n':
        out.append(absl::string_view("\\n"));
        break;
      case '\r':
        out.append(absl::string_view("\\r"));
        break;
      case '\t':
        out.append(absl::string_view("\\t"));
        break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          const std::string escaped = absl::StrCat("\\u00", absl::Hex(static_cast<unsigned char>(c), absl::kZeroPad2));
          out.append(escaped.data(), escaped.data() + escaped.size());
        } else {
          out.push_back(c);
        }
    }
  }
}

void Append(absl::string_view text, spdlog::memory_buf_t& out) { out.append(text.data(), text.data() + text.size()); }

// %~ : the message, escaped for a JSON string.
class JsonMessage final : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&, spdlog::memory_buf_t& out) override {
    AppendJsonEscaped(absl::string_view(msg.payload.data(), msg.payload.size()), out);
  }
  std::unique_ptr<custom_flag_formatter> clone() const override { return std::make_unique<JsonMessage>(); }
};

// %* : the thread's LogContext, as ` session=… principal=…` or as JSON fields.
class ContextFields final : public spdlog::custom_flag_formatter {
 public:
  explicit ContextFields(bool json) : json_(json) {}
  void format(const spdlog::details::log_msg&, const std::tm&, spdlog::memory_buf_t& out) override {
    const LogContext* context = LogContext::Current();
    if (context == nullptr) return;
    for (const auto& [key, value] : {std::pair<absl::string_view, absl::string_view>{"session", context->session()},
                                     {"principal", context->principal()}}) {
      if (value.empty()) continue;
      if (json_) {
        Append(absl::StrCat(",\"", key, "\":\""), out);
        AppendJsonEscaped(value, out);
        out.push_back('"');
      } else {
        Append(absl::StrCat(" ", key, "=", value), out);
      }
    }
  }
  std::unique_ptr<custom_flag_formatter> clone() const override { return std::make_unique<ContextFields>(json_); }

 private:
  const bool json_;
};

// gRPC's own lines (failed TLS handshakes, transport errors) in the same format. Its ERROR
// lines are about one connection (e.g. a client without a certificate), not the server:
// warn.
void LogThroughSpdlog(gpr_log_func_args* args) {
  const spdlog::level::level_enum level = args->severity == GPR_LOG_SEVERITY_DEBUG  ? spdlog::level::debug
                                          : args->severity == GPR_LOG_SEVERITY_INFO ? spdlog::level::info
                                                                                    : spdlog::level::warn;
  spdlog::log(level, "grpc: {} ({}:{})", args->message, args->file, args->line);
}

}  // namespace

absl::StatusOr<std::unique_ptr<spdlog::formatter>> MakeLogFormatter(absl::string_view format) {
  if (format == "text") {
    auto formatter = std::make_unique<spdlog::pattern_formatter>();
    formatter->add_flag<ContextFields>('*', /*json=*/false).set_pattern("[%Y-%m-%d %H:%M:%S.%e] [%l] %v%*");
    return formatter;
  }
  if (format == "json") {
    auto formatter = std::make_unique<spdlog::pattern_formatter>(spdlog::pattern_time_type::utc);
    formatter->add_flag<JsonMessage>('~')
        .add_flag<ContextFields>('*', /*json=*/true)
        .set_pattern(R"({"time":"%Y-%m-%dT%H:%M:%S.%fZ","level":"%l","msg":"%~"%*})");
    return formatter;
  }
  return absl::InvalidArgumentError(absl::StrCat("--log_format = ", format, ": must be text or json"));
}

absl::Status ConfigureLogging(absl::string_view format, absl::string_view level) {
  absl::StatusOr<std::unique_ptr<spdlog::formatter>> formatter = MakeLogFormatter(format);
  if (!formatter.ok()) return formatter.status();
  spdlog::set_formatter(*std::move(formatter));
  spdlog::set_level(spdlog::level::from_str(std::string(level)));
  gpr_set_log_function(LogThroughSpdlog);
  return absl::OkStatus();
}

}  // namespace nupmpc::server
