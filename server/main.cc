// nupmpc-server: the nupmpc.v1 gRPC service. Configuration: --help (flags; environment
// variables NUPMPC_* as fallbacks). SIGTERM/SIGINT drain and exit 0.
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <ctime>

#include "absl/synchronization/mutex.h"
#include "cli/program_flags.h"
#include "server/grpc_server.h"
#include "server/observability/log_format.h"
#include "server/observability/version.h"
#include "server/server_flags.h"
#include "spdlog/spdlog.h"

int main(int argc, char** argv) {
  // Block the stop signals in every thread (gRPC's included); main waits for them.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  // Debian builds Abseil without NDEBUG, which leaves absl::Mutex's lock-order graph (a
  // debugging aid) on for every lock gRPC takes on the request path. The sanitizer builds
  // and tests keep it; the service does not pay it per request.
  absl::SetMutexDeadlockDetectionMode(absl::OnDeadlockCycle::kIgnore);

  absl::StatusOr<nupmpc::server::ParsedFlags> flags = nupmpc::server::ParseServerFlags(argc, argv);
  if (!flags.ok()) return nupmpc::cli::ReportUsageError(nupmpc::server::ServerProgram(), flags.status().message());
  if (absl::Status logging = nupmpc::server::ConfigureLogging(flags->log_format, flags->log_level); !logging.ok()) {
    return nupmpc::cli::ReportUsageError(nupmpc::server::ServerProgram(), logging.message());
  }
  auto server = nupmpc::server::GrpcServer::Start(flags->options);
  if (!server.ok()) {
    spdlog::error("{}", std::string(server.status().message()));
    return 1;
  }
  const nupmpc::server::ServerOptions& o = flags->options;
  spdlog::info("nupmpc-server {} listening on port {} ({}{}; {} workers, queue {}, max {} sessions)",
               nupmpc::server::kVersion, (*server)->port(),
               !o.tls.enabled() ? "plaintext"
               : o.tls.mutual() ? "mTLS"
                                : "TLS",
               o.auth_tokens_file.empty() ? "" : ", bearer tokens", o.worker_threads, o.queue_capacity, o.max_sessions);
  int signal = 0;
  sigwait(&stop_signals, &signal);
  if (flags->drain_delay_s > 0) {
    spdlog::info("signal {}: reporting NOT_SERVING for {} s, still serving (a second signal drains at once)", signal,
                 flags->drain_delay_s);
    (*server)->ReportNotServing();
    // Until the delay is over or a second stop signal comes; other interruptions (EINTR,
    // e.g. after SIGSTOP/SIGCONT) wait on for the rest of the delay.
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(flags->drain_delay_s);
    for (;;) {
      const double left_s = std::chrono::duration<double>(until - std::chrono::steady_clock::now()).count();
      if (left_s <= 0) break;
      const double whole_s = std::floor(left_s);
      const timespec wait{static_cast<time_t>(whole_s), static_cast<long>((left_s - whole_s) * 1e9)};
      if (sigtimedwait(&stop_signals, nullptr, &wait) >= 0 || errno != EINTR) break;
    }
  }
  spdlog::info("draining (grace {} s)", flags->options.grace_period_s);
  (*server)->Shutdown();
  spdlog::info("stopped");
  return 0;
}
