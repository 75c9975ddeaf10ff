#include "server/grpc_server.h"

#include <algorithm>
#include <chrono>
#include <limits>
#include <optional>
#include <thread>

#include "absl/strings/str_cat.h"
#include "grpcpp/ext/proto_server_reflection_plugin.h"
#include "grpcpp/health_check_service_interface.h"
#include "nupmpc/grpc_handover.h"
#include "server/listen_probe.h"
#include "server/metrics_exposition.h"
#include "server/metrics_http.h"
#include "server/observability/process_memory.h"
#include "spdlog/spdlog.h"

namespace nupmpc::server {
namespace {

// A channel argument in milliseconds (an int), from seconds already checked to be > 0.
int Milliseconds(double seconds) {
  return static_cast<int>(std::clamp(seconds * 1e3, 1.0, static_cast<double>(std::numeric_limits<int>::max())));
}

// The clients ping every 2 s (client/client.cc, client/python/nupmpc/security.py); pings
// half that far apart are still accepted, so timer jitter never counts as abuse.
constexpr std::chrono::milliseconds kClientPingIntervalAtLeast{1000};

}  // namespace

absl::StatusOr<std::unique_ptr<GrpcServer>> GrpcServer::Start(const ServerOptions& options) {
  std::unique_ptr<GrpcServer> s(new GrpcServer());
  s->state_ = std::make_unique<ServerState>(options);
  ServerState& state = *s->state_;
  if (!options.auth_tokens_file.empty()) {
    absl::StatusOr<std::unique_ptr<TokenStore>> tokens = TokenStore::Open(options.auth_tokens_file);
    if (!tokens.ok()) return tokens.status();
    state.tokens = *std::move(tokens);
  }
  if (state.tokens != nullptr || options.tls.mutual()) {
    state.auth =
        std::make_shared<AuthProcessor>(state.tokens, options.tls.mutual(), options.tls.trusted_balancer_subject);
  }
  absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials =
      ServerCredentialsFor(options.tls, options.address, state.auth);
  if (!credentials.ok()) return credentials.status();
  if (!options.tls.enabled() && !IsLocalAddress(options.address)) {
    spdlog::warn(
        "listening on {} WITHOUT TLS: anyone who reaches this address can read and drive every session's "
        "traffic; give --tls_cert_file and --tls_key_file (and --auth_tokens_file or --tls_client_ca_file) "
        "outside a trusted network",
        options.address);
  }
  // gRPC and the metrics listener start when any one of an address's resolved addresses
  // binds; a port another process holds on one of them is refused here instead.
  if (const std::optional<ListenHostPort> grpc_tcp = SplitGrpcTcpAddress(options.address); grpc_tcp.has_value()) {
    const absl::Status in_use =
        CheckNotInUse(*grpc_tcp, AnyAddress::kBothFamilies, absl::StrCat("--address ", options.address));
    if (!in_use.ok()) return in_use;
  }
  if (!options.metrics_address.empty()) {
    absl::StatusOr<ListenHostPort> metrics = ParseMetricsAddress(options.metrics_address);
    if (!metrics.ok()) return metrics.status();
    const absl::Status in_use =
        CheckNotInUse(*metrics, AnyAddress::kAsGiven, absl::StrCat("--metrics_address ", options.metrics_address));
    if (!in_use.ok()) return in_use;
  }
  if (!options.state_dir.empty()) {
    SnapshotStoreOptions store;
    store.dir = options.state_dir;
    if (!options.snapshot_key_file.empty()) {
      absl::StatusOr<SnapshotKey> key = SnapshotKey::FromFile(options.snapshot_key_file);
      if (!key.ok()) return key.status();
      store.key = *std::move(key);
    }
    // The spec (one request) and the core's state (within the per-session memory limit),
    // and never more than protobuf parses (kMaxSnapshotBytes).
    store.max_snapshot_bytes = std::min<std::size_t>(
        kMaxSnapshotBytes, static_cast<std::size_t>(options.max_message_bytes) +
                               static_cast<std::size_t>(std::max<long long>(options.size_limits.max_session_bytes, 0)));
    store.reattach_window_s = options.reattach_window_s;
    absl::StatusOr<std::unique_ptr<SnapshotStore>> opened = SnapshotStore::Open(std::move(store));
    if (!opened.ok()) return opened.status();
    state.snapshots = *std::move(opened);
  } else if (!options.snapshot_key_file.empty()) {
    return absl::InvalidArgumentError("--snapshot_key_file: needs --state_dir (the snapshots it seals)");
  }
  s->service_ = std::make_unique<MpcServiceImpl>(s->state_.get());
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  builder.AddListeningPort(options.address, *credentials, &s->port_);
  builder.RegisterService(s->service_.get());
  builder.SetMaxReceiveMessageSize(options.max_message_bytes);
  builder.SetMaxSendMessageSize(options.max_message_bytes);
  // One connection cannot open calls without bound (each Control stream holds a session).
  builder.AddChannelArgument(GRPC_ARG_MAX_CONCURRENT_STREAMS, options.max_streams_per_connection);
  // Peers that connect and say nothing, or stop calling, give their descriptors back
  // (gRPC's own defaults: 120 s for a handshake, no limit for an idle connection).
  builder.AddChannelArgument(GRPC_ARG_SERVER_HANDSHAKE_TIMEOUT_MS, Milliseconds(options.first_message_timeout_s));
  builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_IDLE_MS, Milliseconds(options.connection_idle_timeout_s));
  // A client that vanished without a word (a partition, a frozen machine: its kernel may
  // still acknowledge TCP) holds its streams and sessions until TCP's own timers end the
  // connection, minutes later, or never while a stream is idle. Keepalive pings find it
  // within keepalive_time_s + keepalive_timeout_s; without a limit on pings without data
  // (gRPC's default stops after two), also on a stream that is idle between steps.
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, Milliseconds(options.keepalive_time_s));
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, Milliseconds(options.keepalive_timeout_s));
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  // The clients ping every few seconds, with or without calls; gRPC's default policy (at
  // most one ping in five minutes, none without calls) would answer them with GOAWAY
  // too_many_pings and drop their connections.
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS,
                             static_cast<int>(kClientPingIntervalAtLeast.count()));
  // gRPC binds with SO_REUSEPORT by default, so a second server given a port in use would
  // start and silently take part of its connections; sessions live in one process, so a
  // client's later calls could then reach a server that does not know its session.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  s->server_ = builder.BuildAndStart();
  if (s->server_ == nullptr || s->port_ == 0) {
    return absl::UnavailableError(
        absl::StrCat("could not listen on ", options.address, " (", kListenFailureCauses, ")"));
  }
  s->server_->GetHealthCheckService()->SetServingStatus(true);
  if (!options.metrics_address.empty()) {
    ServerState* state = s->state_.get();
    absl::StatusOr<std::unique_ptr<MetricsHttpServer>> metrics = MetricsHttpServer::Start(
        options.metrics_address, [state] { return RenderPrometheusMetrics(*state); },
        [state] { return state->serving.load(); });
    if (!metrics.ok()) return metrics.status();
    s->metrics_ = *std::move(metrics);
  }
  s->janitor_ = std::thread([raw = s.get()] { raw->Janitor(); });
  return s;
}

GrpcServer::~GrpcServer() { Shutdown(); }

void GrpcServer::Janitor() {
  std::unique_lock<std::mutex> lock(janitor_mu_);
  std::uint64_t closed_at_last_trim = 0;
  while (!stopping_) {
    janitor_wake_.wait_for(lock, std::chrono::seconds(1));
    if (stopping_) break;
    ReloadTokens();
    RevokeStreamsWithoutAccess();
    const int expired = state_->registry.ExpireIdle(state_->options.session_idle_timeout_s);
    if (expired > 0) spdlog::debug("closed {} idle sessions", expired);
    const double compact_after_s = state_->options.session_compact_idle_s;
    const int compacted = compact_after_s > 0.0 ? state_->registry.CompactIdle(compact_after_s) : 0;
    if (compacted > 0) spdlog::debug("released the scratch memory of {} idle sessions", compacted);
    // Once a second at most, and only when memory was freed since the last time.
    if (const std::uint64_t closed = state_->registry.closed_total(); closed != closed_at_last_trim || compacted > 0) {
      closed_at_last_trim = closed;
      ReleaseFreedMemory();
    }
  }
}

void GrpcServer::ReloadTokens() {
  if (state_->tokens == nullptr) return;
  const absl::StatusOr<bool> reloaded = state_->tokens->ReloadIfChanged();
  if (!reloaded.ok()) {
    spdlog::error("{} (the tokens read before stay in effect)", std::string(reloaded.status().message()));
  } else if (*reloaded) {
    spdlog::info("re-read {}: {} tokens", state_->tokens->path(), state_->tokens->size());
  }
}

void GrpcServer::RevokeStreamsWithoutAccess() {
  if (state_->tokens == nullptr) return;
  const TokenStore& tokens = *state_->tokens;
  const std::vector<std::function<void()>> revoked = state_->principal_streams.Revoked(
      [&tokens](const std::string& principal) { return tokens.HasPrincipal(principal); });
  for (const std::function<void()>& revoke : revoked) revoke();
}

void GrpcServer::ReportNotServing() {
  state_->serving.store(false);
  if (server_ != nullptr) server_->GetHealthCheckService()->SetServingStatus(false);
}

void GrpcServer::Shutdown() {
  {
    std::lock_guard<std::mutex> lock(janitor_mu_);
    if (stopping_) return;
    stopping_ = true;
  }
  janitor_wake_.notify_all();
  if (janitor_.joinable()) janitor_.join();
  state_->draining.store(true);
  ReportNotServing();
  // Work already accepted (unary calls, Control steps being solved) finishes within the
  // grace period; then what is left is idle and ends at once: Control streams waiting for
  // their next step get UNAVAILABLE, idle connections are closed. (gRPC's own Shutdown
  // with a deadline waits for open streams until the deadline, and on idle connections
  // for up to seconds even when no call is open.)
  const auto grace_end =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(state_->options.grace_period_s);
  while (state_->work_in_flight.load() > 0 && std::chrono::steady_clock::now() < grace_end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  // Before the streams end (and their sessions with them): no step is accepted any more, so
  // every idle session's snapshot is what its next step would start from.
  if (state_->snapshots != nullptr) {
    // A solve still running past the grace period gets a second more to finish.
    const Clock::time_point until =
        std::max(std::chrono::time_point_cast<Clock::duration>(grace_end), Clock::now()) + std::chrono::seconds(1);
    const int written = state_->WriteSnapshots(until);
    spdlog::info("wrote {} session snapshots of {} to {}", written, state_->registry.size(), state_->snapshots->dir());
  }
  if (server_ != nullptr) {
    server_->Shutdown(std::chrono::system_clock::now());
    TakeFromGrpc(state_.get());  // every call's OnDone has run (server/rpc/grpc_handover.h)
  }
  state_->pool.Shutdown();
  metrics_.reset();  // last: scrapes see the drain to its end
}

}  // namespace nupmpc::server
