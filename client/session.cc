#include "client/session.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "client/spec_update.h"

namespace nupmpc {
namespace {

using Clock = ControlCall::Clock;

// What a step that got no answer within its period returns.
v1::SolveResult HeldResult() {
  v1::SolveResult result;
  result.set_status(v1::SOLVE_STATUS_HELD);
  result.set_has_plan(false);
  result.set_objective(std::numeric_limits<double>::quiet_NaN());
  result.set_max_violation(std::numeric_limits<double>::quiet_NaN());
  return result;
}

// How many sent steps wait for an answer at most: more than K of them means the stream
// is already counted as broken (their answers would only update the spec).
constexpr std::size_t kMaxUnanswered = 256;

}  // namespace

int ControlPeriod::HeldPeriodsToReconnect() const {
  if (held_periods_to_reconnect > 0) return held_periods_to_reconnect;
  const double period_s = std::max(std::chrono::duration<double>(period).count(), 1e-3);
  const auto per_second = static_cast<int>(std::ceil(1.0 / period_s));
  return std::max(3, per_second);
}

Session::Session(Client* client, v1::ProblemSpec spec, ReconnectOptions reconnect, ControlPeriod period)
    : client_(client),
      reconnect_(std::move(reconnect)),
      period_(period),
      channel_(client->channel_),
      spec_(std::move(spec)) {
  // The server learns the period as the session's deadline (ProblemSpec.timing), unless
  // the spec sets one of its own.
  if (period_.period.count() > 0 && spec_.timing().period_ms() == 0.0) {
    spec_.mutable_timing()->set_period_ms(std::chrono::duration<double, std::milli>(period_.period).count());
  }
}

Session::~Session() { (void)Close(); }

std::string Session::id() const {
  std::lock_guard<std::mutex> lock(mu_);
  return id_;
}

int Session::reconnects() const {
  std::lock_guard<std::mutex> lock(mu_);
  return stats_.reconnects;
}

ReconnectStats Session::reconnect_stats() const {
  std::lock_guard<std::mutex> lock(mu_);
  return stats_;
}

int Session::held_steps() const {
  std::lock_guard<std::mutex> lock(mu_);
  return held_steps_;
}

int Session::consecutive_held_steps() const {
  std::lock_guard<std::mutex> lock(mu_);
  return consecutive_held_;
}

int Session::late_answers() const {
  std::lock_guard<std::mutex> lock(mu_);
  return late_answers_;
}

namespace {

// Opens a Control call whose first message is `hello` and waits until `deadline` for the
// server's answer to it; sets *id.
absl::StatusOr<std::shared_ptr<ControlCall>> OpenCall(std::shared_ptr<grpc::Channel> channel,
                                                      const v1::ControlRequest& hello, Clock::time_point deadline,
                                                      std::string* id) {
  auto call = std::make_shared<ControlCall>(std::move(channel), hello);
  absl::StatusOr<std::optional<v1::ControlResponse>> response = call->WaitFor(hello.sequence(), deadline, {});
  if (!response.ok()) return response.status();
  if (!response->has_value()) return absl::UnavailableError("no session within the attempt timeout");
  const v1::ControlResponse& answer = **response;
  if (answer.error_code() != 0) {
    return absl::Status(static_cast<absl::StatusCode>(answer.error_code()), answer.error_message());
  }
  // The server names the session in its answer; an attach by id names the one it asked for.
  *id = answer.session_id().empty() ? hello.session_id() : answer.session_id();
  return call;
}

}  // namespace

absl::StatusOr<std::shared_ptr<ControlCall>> Session::Attach(const std::shared_ptr<grpc::Channel>& channel,
                                                             const std::string& old_id, const v1::ProblemSpec& spec,
                                                             std::uint64_t sequence, Clock::time_point deadline,
                                                             std::string* id, ReconnectAttempt* report) {
  std::shared_ptr<ControlCall> call;
  const auto open = [&](const v1::ControlRequest& hello) -> absl::Status {
    absl::StatusOr<std::shared_ptr<ControlCall>> opened = OpenCall(channel, hello, deadline, id);
    if (!opened.ok()) return opened.status();
    call = *std::move(opened);
    return absl::OkStatus();
  };
  const absl::Status s = ReattachOrRecreate(
      old_id,
      [&] {
        v1::ControlRequest hello;  // attach-only: the unanswered step is resent on the call after this
        hello.set_session_id(old_id);
        hello.set_sequence(sequence);
        return open(hello);
      },
      [&] {
        v1::ControlRequest hello;
        *hello.mutable_spec() = spec;
        hello.set_sequence(sequence);
        return open(hello);
      },
      report);
  if (!s.ok()) return s;
  return call;
}

absl::Status Session::ConnectLocked(std::chrono::milliseconds timeout, ReconnectAttempt* report) {
  std::string id;
  absl::StatusOr<std::shared_ptr<ControlCall>> call =
      Attach(channel_, id_, spec_, next_sequence_++, Clock::now() + timeout, &id, report);
  if (!call.ok()) return call.status();
  call_ = *std::move(call);
  id_ = std::move(id);
  return absl::OkStatus();
}

void Session::RenewChannelLocked() {
  // A channel whose connection attempts were refused while the server was down keeps
  // failing calls at once until its own back-off (1 s growing ×1.6 to 2 min) lets it try
  // again: seconds after the server is back. So every attempt is made on a new channel with
  // a connection of its own, which connects now; the session keeps the one that worked.
  // (Built from a channel, the client has no target to open another: then its channel is
  // told to retry now, which gRPC may honour late.)
  if (!client_->target_.empty()) {
    channel_ = client_->NewChannel(/*own_subchannel=*/true);
  } else {
    grpc::experimental::ChannelResetConnectionBackoff(channel_.get());
  }
}

void Session::TakeLateAnswer(const v1::ControlResponse& response) {
  std::lock_guard<std::mutex> lock(mu_);
  silent_periods_ = 0;  // the stream is alive, only slower than the period
  auto it = unanswered_.find(response.sequence());
  if (it == unanswered_.end()) return;
  ++late_answers_;
  const bool solved = response.error_code() == 0 && response.result().status() != v1::SOLVE_STATUS_SUPERSEDED;
  if (!solved) {
    // A refusal or a SUPERSEDED answer comes at once, ahead of the solve in progress of an
    // earlier step: only this step is settled, and nothing of it applied.
    unanswered_.erase(it);
    return;
  }
  // The server applied the step: so does the spec. Solves run one at a time and answers
  // of earlier steps were sent before this one's: none of them is still to come.
  ApplyStepToSpec(it->second, response.result(), &spec_);
  unanswered_.erase(unanswered_.begin(), std::next(it));
}

absl::StatusOr<std::optional<v1::SolveResult>> Session::Exchange(const v1::Step& step, Clock::time_point deadline) {
  std::shared_ptr<ControlCall> call;
  v1::ControlRequest request;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (call_ == nullptr) return absl::UnavailableError("not connected");
    call = call_;
    request.set_sequence(next_sequence_++);
    *request.mutable_step() = step;
    request.set_held_periods(static_cast<std::uint32_t>(std::exchange(unreported_held_, 0)));
    unanswered_.emplace(request.sequence(), step);
    // At least K of them: past that the stream counts as broken anyway.
    const auto most = std::max<std::size_t>(kMaxUnanswered, 2 * period_.HeldPeriodsToReconnect());
    if (unanswered_.size() > most) unanswered_.erase(unanswered_.begin());
    // A step still waiting behind a stalled write is dropped unsent: nothing of it applies.
    if (std::optional<std::uint64_t> dropped = call->Send(request); dropped.has_value()) unanswered_.erase(*dropped);
  }
  absl::StatusOr<std::optional<v1::ControlResponse>> response =
      call->WaitFor(request.sequence(), deadline, [this](const v1::ControlResponse& r) { TakeLateAnswer(r); });
  std::lock_guard<std::mutex> lock(mu_);
  if (!response.ok()) {
    // The session is gone with its stream; a re-created one starts from the spec.
    BreakLocked(call, response.status());
    return response.status();
  }
  if (!response->has_value()) return std::nullopt;  // held: the answer may still come
  silent_periods_ = 0;
  unanswered_.erase(request.sequence());
  v1::ControlResponse& answer = **response;
  if (answer.error_code() != 0) {
    return absl::Status(static_cast<absl::StatusCode>(answer.error_code()), answer.error_message());
  }
  ApplyStepToSpec(step, answer.result(), &spec_);
  return std::move(*answer.mutable_result());
}

absl::StatusOr<v1::SolveResult> Session::Step(const v1::Step& step) {
  std::lock_guard<std::mutex> serial(step_mu_);
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (closing_) return absl::FailedPreconditionError("the session was closed");
  }
  return period_.period.count() > 0 ? StepInPeriod(step) : StepWaiting(step);
}

absl::StatusOr<v1::SolveResult> Session::StepWaiting(const v1::Step& step) {
  const auto no_deadline = Clock::time_point::max();
  absl::StatusOr<std::optional<v1::SolveResult>> result = Exchange(step, no_deadline);
  if (!result.ok() && IsRetryable(result.status())) {
    // The stream (or the server) went away: get the session back (by its id, else
    // re-created from the spec) and resend the step, with back-off, until the budget is
    // spent. The step is resent once per attempt that got a session, on that session's
    // new stream only, and its answer is matched by its new sequence number: the result
    // returned is this step's.
    std::unique_lock<std::mutex> lock(mu_);
    call_.reset();
    const absl::Status outage = RideOutOutage(
        reconnect_, result.status(),
        [&](std::chrono::milliseconds timeout, ReconnectAttempt* report, bool* answered) -> absl::Status {
          RenewChannelLocked();
          if (absl::Status s = ConnectLocked(timeout, report); !s.ok()) return s;
          lock.unlock();
          result = Exchange(step, no_deadline);
          lock.lock();
          *answered = result.ok() || !IsRetryable(result.status());
          if (!*answered) call_.reset();
          return result.status();
        },
        &stats_);
    // Answered: `result` is the resent step's answer (or its own error).
    if (!outage.ok()) return outage;
  }
  if (!result.ok()) return result.status();
  return **std::move(result);
}

void Session::BreakLocked(const std::shared_ptr<ControlCall>& call, const absl::Status& cause) {
  if (call_ == nullptr || call_ != call) return;  // already broken (and maybe replaced)
  call_->Cancel();
  call_.reset();
  unanswered_.clear();
  break_cause_ = cause;
  broken_at_ = Clock::now();
  changed_.notify_all();
}

absl::StatusOr<v1::SolveResult> Session::StepInPeriod(const v1::Step& step) {
  const Clock::time_point called_at = Clock::now(), deadline = called_at + period_.period;
  std::shared_ptr<ControlCall> call;
  {
    std::unique_lock<std::mutex> lock(mu_);
    last_step_at_ = called_at;
    // A copy: BreakLocked resets call_, which a reference to it would then see reset too.
    if (const std::shared_ptr<ControlCall> ended = call_; ended != nullptr && ended->Ended()) {
      BreakLocked(ended, absl::UnavailableError("the Control stream ended"));
    }
    // Wake the reconnect thread (it pauses while nobody steps), then wait for it as long
    // as the period allows.
    changed_.notify_all();
    changed_.wait_until(lock, deadline, [this] { return call_ != nullptr || closing_; });
    call = call_;
  }
  absl::StatusOr<std::optional<v1::SolveResult>> result =
      call == nullptr ? absl::StatusOr<std::optional<v1::SolveResult>>(std::nullopt) : Exchange(step, deadline);
  std::lock_guard<std::mutex> lock(mu_);
  if (!result.ok() && IsRetryable(result.status())) {
    BreakLocked(call, result.status());
    result = std::nullopt;
  }
  if (!result.ok()) return result.status();  // the step's own error (a bad update): not a held period
  if (result->has_value()) {
    consecutive_held_ = 0;
    return **std::move(result);
  }
  ++held_steps_;
  ++consecutive_held_;
  ++unreported_held_;
  // Late answers reset silent_periods_: a live server slower than the period keeps its
  // stream (and its warm start); only one that answers nothing at all is left.
  if (call != nullptr && ++silent_periods_ >= period_.HeldPeriodsToReconnect()) {
    BreakLocked(call, absl::UnavailableError(absl::StrCat("no answer in ", silent_periods_, " periods in a row")));
  }
  return HeldResult();
}

void Session::ReconnectLoop() {
  ReconnectOptions options = reconnect_;
  options.max_backoff = std::min(options.max_backoff, ControlPeriod::kMaxBackoff);
  options.attempt_timeout = std::min(options.attempt_timeout, ControlPeriod::kMaxAttemptTimeout);
  // The caller keeps stepping when its last step is this recent.
  const auto stepping = std::max<Clock::duration>(std::chrono::seconds(1), 2 * period_.period);
  Backoff backoff(options);
  int attempt = 0;
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    changed_.wait(lock, [&] { return closing_ || (call_ == nullptr && Clock::now() - last_step_at_ < stepping); });
    if (closing_) return;
    if (attempt == 0) backoff.Reset();
    // Capped after the jitter too: at most kMaxBackoff between attempts, as documented.
    const std::chrono::milliseconds wait = std::min(backoff.Next(), ControlPeriod::kMaxBackoff);
    if (changed_.wait_for(lock, wait, [this] { return closing_; })) return;
    RenewChannelLocked();
    std::shared_ptr<grpc::Channel> channel = channel_;
    const std::string old_id = id_;
    const v1::ProblemSpec spec = spec_;
    const std::uint64_t sequence = next_sequence_++;
    std::string id;
    ReconnectAttempt report;
    lock.unlock();
    absl::StatusOr<std::shared_ptr<ControlCall>> call =
        Attach(channel, old_id, spec, sequence, Clock::now() + options.attempt_timeout, &id, &report);
    lock.lock();
    report.attempt = ++attempt;
    report.waited = wait;
    report.cause = break_cause_;
    report.result = call.status();
    report.elapsed = std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - broken_at_);
    ++stats_.attempts;
    if (call.ok() && !closing_) {
      call_ = *std::move(call);
      id_ = std::move(id);
      silent_periods_ = 0;
      CountReconnect(report.path, &stats_);
      stats_.total += report.elapsed;
      stats_.longest = std::max(stats_.longest, report.elapsed);
      attempt = 0;
      changed_.notify_all();
    } else {
      break_cause_ = call.status();
    }
    if (options.on_attempt) {
      // Not under the lock: the callback may ask the session for its figures.
      lock.unlock();
      options.on_attempt(report);
      lock.lock();
    }
  }
}

std::future<absl::StatusOr<v1::SolveResult>> Session::StepAsync(v1::Step step) {
  return std::async(std::launch::async, [this, step = std::move(step)] { return Step(step); });
}

absl::Status Session::Close() {
  std::lock_guard<std::mutex> serial(step_mu_);
  std::shared_ptr<ControlCall> call;
  {
    std::lock_guard<std::mutex> lock(mu_);
    closing_ = true;
    changed_.notify_all();
    call = std::move(call_);
  }
  if (reconnector_.joinable()) reconnector_.join();
  if (call == nullptr) return absl::OkStatus();
  if (period_.period.count() > 0) {
    // Bounded, and quiet: a server that does not say goodbye within a second, or a stream
    // that broke unnoticed, leaves nothing to report to a loop that is ending anyway.
    (void)call->Finish(Clock::now() + std::chrono::seconds(1));
    return absl::OkStatus();
  }
  const grpc::Status s = call->Finish(Clock::time_point::max());
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
}

}  // namespace nupmpc
