#include "loadtest/echo_server.h"

#include <chrono>
#include <deque>
#include <mutex>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "loadtest/instances/benchmark_instance.h"
#include "loadtest/step_as_server.h"
#include "server/convert/result_conversion.h"
#include "server/scheduling/thread_cpu_time.h"
#include "server/sessions/session_factory.h"

namespace nupmpc::loadtest {
namespace {

// One echoed Control stream. Reads and writes overlap (an open-loop client sends before
// its previous answer is written), so answers wait in a queue and go out one at a time.
// Without a fixed answer (the bare peer), the stream solves its own session instead.
class EchoStream : public grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse> {
 public:
  EchoStream(const v1::SolveResult* answer, const std::vector<std::chrono::nanoseconds>* busy)
      : answer_(answer), busy_(busy) {
    StartRead(&incoming_);
  }

  void OnReadDone(bool ok) override {
    if (ok && incoming_.has_step() && !busy_->empty()) {
      // Stands in for a solve done right here: busy, not asleep, as a solve would be, for
      // that much of this thread's CPU time (not wall time: two reactions spinning at once
      // on one core would each count the other's time as their own, doing two "solves" in
      // the time of one).
      const std::chrono::nanoseconds until = server::ThreadCpuTime() + (*busy_)[steps_++ % busy_->size()];
      while (server::ThreadCpuTime() < until) {
      }
    }
    // The answer is built before the lock: a solve must not hold up OnWriteDone.
    v1::ControlResponse response;
    if (ok) {
      response.set_sequence(incoming_.sequence());
      if (answer_ == nullptr) {
        AnswerBySolving(response);
      } else if (incoming_.has_step()) {
        *response.mutable_result() = *answer_;
      } else {
        response.set_session_id("echo");
      }
    }
    std::unique_lock<std::mutex> lock(mu_);
    if (!ok) {
      reads_done_ = true;
      FinishIfIdleLocked(lock);
      return;
    }
    writes_.push_back(std::move(response));
    const bool start_write = !writing_;
    writing_ = true;
    lock.unlock();
    StartRead(&incoming_);
    if (start_write) StartWrite(&writes_.front());
  }

  void OnWriteDone(bool ok) override {
    std::unique_lock<std::mutex> lock(mu_);
    writes_.pop_front();
    if (!ok) writes_.clear();
    if (writes_.empty()) {
      writing_ = false;
      if (!ok) reads_done_ = true;
      FinishIfIdleLocked(lock);
      return;
    }
    const v1::ControlResponse* next = &writes_.front();  // deque: stable while others are appended
    lock.unlock();
    StartWrite(next);
  }

  void OnDone() override { delete this; }

 private:
  // The bare peer: the session built from the stream's first message (its spec, as the
  // server admits it but without limits) and each step solved right here as the server's
  // SolveStep does (StepAsTheServerDoes), answered with the real result; what fails is
  // answered as an error.
  void AnswerBySolving(v1::ControlResponse& response) {
    if (incoming_.has_spec()) {
      absl::StatusOr<server::BuiltSession> built = server::BuildSession(incoming_.spec(), bench::NoSizeLimits());
      if (!built.ok()) return Refuse(built.status(), response);
      session_ = *std::move(built);
      response.set_session_id("bare");
    }
    if (!incoming_.has_step()) return;
    if (!session_.has_value()) {
      return Refuse(absl::FailedPreconditionError("spec: the stream's first message carries none"), response);
    }
    absl::StatusOr<core::SolveSummary> summary = StepAsTheServerDoes(*session_, incoming_.step(), &solution_);
    if (!summary.ok()) return Refuse(summary.status(), response);
    server::ResultToProto(*summary, solution_, response.mutable_result());
  }

  static void Refuse(const absl::Status& status, v1::ControlResponse& response) {
    response.set_error_code(static_cast<int>(status.code()));
    response.set_error_message(std::string(status.message()));
  }

  void FinishIfIdleLocked(std::unique_lock<std::mutex>& lock) {
    if (!reads_done_ || writing_ || finished_) return;
    finished_ = true;
    lock.unlock();
    Finish(grpc::Status::OK);
  }

  const v1::SolveResult* const answer_;
  const std::vector<std::chrono::nanoseconds>* const busy_;
  std::size_t steps_ = 0;                        ///< steps read (reads are one at a time)
  std::optional<server::BuiltSession> session_;  ///< the bare peer's
  core::Solution solution_;
  v1::ControlRequest incoming_;
  std::mutex mu_;
  std::deque<v1::ControlResponse> writes_;
  bool writing_ = false;
  bool reads_done_ = false;
  bool finished_ = false;
};

}  // namespace

class EchoControlServer::Service : public v1::MpcService::CallbackService {
 public:
  Service(std::optional<v1::SolveResult> answer, std::vector<std::chrono::nanoseconds> busy)
      : answer_(std::move(answer)), busy_(std::move(busy)) {}

  grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse>* Control(
      grpc::CallbackServerContext* /*context*/) override {
    return new EchoStream(answer_.has_value() ? &*answer_ : nullptr, &busy_);
  }

 private:
  const std::optional<v1::SolveResult> answer_;  ///< none: the bare peer, which solves
  const std::vector<std::chrono::nanoseconds> busy_;
};

absl::StatusOr<std::unique_ptr<EchoControlServer>> EchoControlServer::Start(
    v1::SolveResult answer, std::vector<std::chrono::nanoseconds> busy) {
  return Listen(std::make_unique<Service>(std::move(answer), std::move(busy)));
}

absl::StatusOr<std::unique_ptr<EchoControlServer>> EchoControlServer::StartSolving() {
  return Listen(std::make_unique<Service>(std::nullopt, std::vector<std::chrono::nanoseconds>{}));
}

absl::StatusOr<std::unique_ptr<EchoControlServer>> EchoControlServer::Listen(std::unique_ptr<Service> service) {
  std::unique_ptr<EchoControlServer> s(new EchoControlServer());
  s->service_ = std::move(service);
  grpc::ServerBuilder builder;
  builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &s->port_);
  builder.RegisterService(s->service_.get());
  builder.SetMaxReceiveMessageSize(-1);
  s->server_ = builder.BuildAndStart();
  if (s->server_ == nullptr || s->port_ == 0)
    return absl::UnavailableError("echo server: could not listen on 127.0.0.1");
  return s;
}

EchoControlServer::~EchoControlServer() {
  if (server_ != nullptr) server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
}

std::string EchoControlServer::target() const { return absl::StrCat("127.0.0.1:", port_); }

}  // namespace nupmpc::loadtest
