#ifndef NUPMPC_TESTS_CLIENT_SCRIPTED_CONTROL_H_
#define NUPMPC_TESTS_CLIENT_SCRIPTED_CONTROL_H_

// A Control service whose answers the test scripts, on a real gRPC server in the test's
// process: the tests of nupmpc::Session decide when (or whether) each step is answered,
// whether a stream breaks, and whether a session can be attached again by its id, so the
// client's mechanisms are checked without depending on the machine's speed or on what a
// real server does today.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_format.h"
#include "client/session_routing.h"
#include "grpcpp/grpcpp.h"
#include "nupmpc/grpc_handover.h"
#include "nupmpc/v1/nupmpc.grpc.pb.h"

namespace nupmpc::testing {

// Each step is answered after delay(attach number, the step's state[0]), or never for a
// negative delay, as SUPERSEDED when superseded(attach, x0) says so; its stream is ended
// with UNAVAILABLE instead of an answer when breaks(attach, x0) says so (a server that
// drained or went away with the step). An answer's objective is the step's state[0], so a
// test sees which step a result belongs to. The attach number counts the streams that got
// a session, by spec or by id, from 1. A stream attaching by id gets what attach_by_id(id)
// says: OK attaches it (the server kept the session), an error ends the stream with it.
class ScriptedControl final : public v1::MpcService::CallbackService {
 public:
  std::function<std::chrono::milliseconds(int attach, double x0)> delay = [](int, double) {
    return std::chrono::milliseconds(0);
  };
  std::function<bool(int attach, double x0)> superseded = [](int, double) { return false; };
  std::function<bool(int attach, double x0)> breaks = [](int, double) { return false; };
  // Default: what a server gives for a session it does not hold.
  std::function<grpc::Status(const std::string& id)> attach_by_id = [](const std::string&) {
    return grpc::Status(grpc::StatusCode::NOT_FOUND, "session_id: no such session");
  };

  // One stream's first message as the service saw it.
  struct Attach {
    std::string session_id;      // attached by this id; empty: created from `spec`
    v1::ProblemSpec spec;        // when created
    std::string routing_header;  // the x-nupmpc-session header the call carried
    bool accepted = false;
  };
  // One step the service received.
  struct Received {
    int attach = 0;  // the stream's attach number
    double x0 = 0.0;
    std::uint64_t sequence = 0;
  };

  // Sessions created from a spec (attaches by id not counted).
  int attaches() const {
    std::lock_guard<std::mutex> lock(mu_);
    int created = 0;
    for (const Attach& a : attach_log_) created += a.session_id.empty() ? 1 : 0;
    return created;
  }
  // The spec of the k-th session created (from 0).
  v1::ProblemSpec attach_spec(int k) const {
    std::lock_guard<std::mutex> lock(mu_);
    for (const Attach& a : attach_log_) {
      if (a.session_id.empty() && k-- == 0) return a.spec;
    }
    return {};
  }
  std::vector<Attach> attach_log() const {
    std::lock_guard<std::mutex> lock(mu_);
    return attach_log_;
  }
  std::vector<Received> received() const {
    std::lock_guard<std::mutex> lock(mu_);
    return received_;
  }

  grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse>* Control(
      grpc::CallbackServerContext* context) override {
    std::string header;
    const auto& metadata = context->client_metadata();
    if (auto it = metadata.find(kSessionHeader); it != metadata.end())
      header.assign(it->second.data(), it->second.size());
    return new Stream(this, std::move(header));
  }

 private:
  class Stream : public grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse> {
   public:
    Stream(ScriptedControl* service, std::string header) : service_(service), header_(std::move(header)) {
      std::lock_guard<std::mutex> lock(mu_);
      HandToGrpc(this);
      StartRead(&request_);
    }
    ~Stream() override {
      std::vector<std::thread> answerers;
      {
        std::lock_guard<std::mutex> lock(mu_);
        answerers.swap(answerers_);
      }
      for (std::thread& t : answerers) t.join();
    }

    void OnReadDone(bool ok) override {
      TakeFromGrpc(this);
      if (!ok) {
        FinishOnce(grpc::Status::OK);
        return;
      }
      // Under the stream's lock: gRPC hands the reactions from thread to thread through its
      // own synchronisation, which ThreadSanitizer does not see.
      std::unique_lock<std::mutex> lock(mu_);
      v1::ControlResponse response;
      response.set_sequence(request_.sequence());
      if (request_.attach_case() != v1::ControlRequest::ATTACH_NOT_SET) {
        if (!AttachLocked(&response)) return;
      } else {
        const double x0 = request_.step().state(0);
        {
          std::lock_guard<std::mutex> service_lock(service_->mu_);
          service_->received_.push_back({attach_, x0, request_.sequence()});
        }
        if (service_->breaks(attach_, x0)) {
          lock.unlock();
          FinishOnce(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the scripted server went away"));
          return;
        }
        if (service_->superseded(attach_, x0)) {
          response.mutable_result()->set_status(v1::SOLVE_STATUS_SUPERSEDED);
        } else {
          response.mutable_result()->set_status(v1::SOLVE_STATUS_CONVERGED);
          response.mutable_result()->set_has_plan(true);
          response.mutable_result()->set_objective(x0);
          response.mutable_result()->add_inputs(x0);
        }
        const std::chrono::milliseconds delay = service_->delay(attach_, x0);
        if (delay.count() >= 0) AnswerLocked(response, delay);
      }
      request_.Clear();
      if (finished_) return;
      HandToGrpc(this);
      StartRead(&request_);
    }
    void OnWriteDone(bool /*ok*/) override {
      TakeFromGrpc(this);
      std::lock_guard<std::mutex> lock(mu_);
      writing_ = false;
      if (!queue_.empty() && !finished_) WriteNextLocked();
    }
    void OnDone() override {
      TakeFromGrpc(this);
      {
        std::lock_guard<std::mutex> lock(mu_);
        done_ = true;
      }
      done_changed_.notify_all();
      // The answerer threads may still be sleeping: let them end before this is freed.
      std::thread([this] { delete this; }).detach();
    }
    void OnCancel() override {
      TakeFromGrpc(this);
      FinishOnce(grpc::Status::CANCELLED);
    }

   private:
    // The first message: answers it (true) or ends the stream with the refusal (false).
    // Under mu_.
    bool AttachLocked(v1::ControlResponse* response) {
      Attach attach;
      attach.routing_header = header_;
      grpc::Status refusal;
      if (request_.has_spec()) {
        attach.spec = request_.spec();
      } else {
        attach.session_id = request_.session_id();
        refusal = service_->attach_by_id(attach.session_id);
      }
      attach.accepted = refusal.ok();
      {
        std::lock_guard<std::mutex> service_lock(service_->mu_);
        service_->attach_log_.push_back(attach);
        if (attach.accepted) attach_ = ++service_->sessions_;
        // Ids of the server's form (32 hex digits), so that the client routes by them.
        response->set_session_id(attach.session_id.empty() ? absl::StrFormat("%032x", attach_) : attach.session_id);
      }
      if (!attach.accepted) {
        finished_ = true;
        HandToGrpc(this);
        Finish(refusal);
        return false;
      }
      AnswerLocked(*response, std::chrono::milliseconds(0));
      return true;
    }
    void FinishOnce(const grpc::Status& status) {
      std::lock_guard<std::mutex> lock(mu_);
      if (finished_) return;
      finished_ = true;
      HandToGrpc(this);
      Finish(status);
    }
    // Writes `response` after `delay` (one write at a time, in order of their times). Under mu_.
    void AnswerLocked(v1::ControlResponse response, std::chrono::milliseconds delay) {
      answerers_.emplace_back([this, response = std::move(response), delay] {
        std::unique_lock<std::mutex> lock(mu_);
        if (done_changed_.wait_for(lock, delay, [this] { return done_; })) return;
        if (finished_) return;
        queue_.push_back(response);
        if (!writing_) WriteNextLocked();
      });
    }
    void WriteNextLocked() {
      writing_ = true;
      writing_response_ = queue_.front();
      queue_.erase(queue_.begin());
      HandToGrpc(this);
      StartWrite(&writing_response_);
    }

    ScriptedControl* service_;
    const std::string header_;
    v1::ControlRequest request_;
    int attach_ = 0;
    std::vector<std::thread> answerers_;
    std::mutex mu_;
    std::condition_variable done_changed_;
    bool done_ = false;
    bool finished_ = false;
    bool writing_ = false;
    std::vector<v1::ControlResponse> queue_;
    v1::ControlResponse writing_response_;
  };

  mutable std::mutex mu_;
  std::vector<Attach> attach_log_;
  std::vector<Received> received_;
  int sessions_ = 0;
};

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_CLIENT_SCRIPTED_CONTROL_H_
