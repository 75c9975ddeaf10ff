#include "loadtest/load_stream.h"

#include <cmath>
#include <utility>

#include "absl/status/status.h"

namespace nupmpc::loadtest {
namespace {

std::string CodeName(int code) { return absl::StatusCodeToString(static_cast<absl::StatusCode>(code)); }

}  // namespace

v1::PriorUpdate MovingReferences(const v1::ProblemSpec& spec, std::uint64_t sequence) {
  v1::PriorUpdate update;
  for (int k = 0; k < spec.output_priors_size(); ++k) {
    v1::PriorUpdate::Entry* entry = update.add_outputs();
    entry->set_index(static_cast<std::uint32_t>(k));
    *entry->mutable_prior() = spec.output_priors(k);  // weights and bounds stay as specified
    entry->mutable_prior()->clear_target();
    entry->mutable_prior()->add_target(0.5 * std::sin(0.05 * static_cast<double>(sequence) + k));
  }
  return update;
}

void StreamTally::MergeFrom(const StreamTally& other) {
  latency_ms.insert(latency_ms.end(), other.latency_ms.begin(), other.latency_ms.end());
  service_ms.insert(service_ms.end(), other.service_ms.begin(), other.service_ms.end());
  solve_ms.insert(solve_ms.end(), other.solve_ms.begin(), other.solve_ms.end());
  iterations += other.iterations;
  sent += other.sent;
  superseded += other.superseded;
  no_plan += other.no_plan;
  for (const auto& [code, n] : other.errors) errors[code] += n;
}

LoadStream::LoadStream(v1::MpcService::Stub* stub, StreamPlan plan) : plan_(plan) {
  stub->async()->Control(&context_, this);
}

grpc::Status LoadStream::Open() {
  const v1::ControlRequest* first = nullptr;
  {
    std::lock_guard<std::mutex> lock(mu_);
    v1::ControlRequest attach;
    *attach.mutable_spec() = *plan_.spec;
    write_queue_.push_back(std::move(attach));
    writing_ = true;
    first = &write_queue_.front();
  }
  StartRead(&incoming_);
  StartWrite(first);
  StartCall();
  std::unique_lock<std::mutex> lock(mu_);
  changed_.wait(lock, [&] { return session_ready_ || done_; });
  if (!session_ready_)
    return final_status_.ok() ? grpc::Status(grpc::StatusCode::UNKNOWN, "stream ended") : final_status_;
  return grpc::Status::OK;
}

void LoadStream::BeginMeasuring(Clock::time_point from, Clock::time_point until) {
  const v1::ControlRequest* to_write = nullptr;
  {
    std::lock_guard<std::mutex> lock(mu_);
    measure_from_ = from;
    measure_until_ = until;
    if (!plan_.closed_loop) return;
    SendLocked(Clock::now());
    if (!writing_) {
      writing_ = true;
      to_write = &write_queue_.front();
    }
  }
  if (to_write != nullptr) StartWrite(to_write);
}

void LoadStream::Send(Clock::time_point arrival) {
  const v1::ControlRequest* to_write = nullptr;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!session_ready_ || stopping_ || done_) return;
    SendLocked(arrival);
    if (!writing_) {
      writing_ = true;
      to_write = &write_queue_.front();
    }
  }
  if (to_write != nullptr) StartWrite(to_write);
}

void LoadStream::SendLocked(Clock::time_point scheduled) {
  const std::vector<std::vector<double>>& states = *plan_.states;
  v1::ControlRequest request;
  request.set_sequence(next_sequence_);
  v1::Step* step = request.mutable_step();
  const std::vector<double>& x = states[next_state_];
  step->mutable_state()->Add(x.begin(), x.end());
  // Wrapping around starts a new episode at the instance's first state: a cold start,
  // as the core baseline does.
  if (next_state_ == 0 && next_sequence_ > 1) step->set_warm_start(v1::WARM_START_COLD);
  if (plan_.new_references) *step->mutable_update() = MovingReferences(*plan_.spec, next_sequence_);
  next_state_ = (next_state_ + 1) % states.size();
  outstanding_.emplace(next_sequence_, Outstanding{scheduled, Clock::now()});
  ++next_sequence_;
  if (Counted(scheduled)) ++tally_.sent;
  write_queue_.push_back(std::move(request));
}

void LoadStream::OnWriteDone(bool ok) {
  const v1::ControlRequest* to_write = nullptr;
  bool writes_done = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    write_queue_.pop_front();
    if (!ok) {  // the stream broke; OnDone reports why
      write_queue_.clear();
      writing_ = false;
      return;
    }
    if (!write_queue_.empty()) {
      to_write = &write_queue_.front();
    } else {
      writing_ = false;
      if (stopping_ && !writes_done_sent_) writes_done = writes_done_sent_ = true;
    }
  }
  if (to_write != nullptr) StartWrite(to_write);
  if (writes_done) StartWritesDone();
}

void LoadStream::OnReadDone(bool ok) {
  if (!ok) return;  // the server ended the stream; OnDone follows
  const Clock::time_point now = Clock::now();
  const v1::ControlRequest* to_write = nullptr;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!session_ready_) {
      if (incoming_.error_code() == 0 && !incoming_.session_id().empty()) session_ready_ = true;
    } else {
      RecordLocked(incoming_, now);
      const bool final_answer = incoming_.result().status() != v1::SOLVE_STATUS_SUPERSEDED;
      if (plan_.closed_loop && final_answer && !stopping_) {
        SendLocked(now);
        if (!writing_) {
          writing_ = true;
          to_write = &write_queue_.front();
        }
      }
    }
    changed_.notify_all();
  }
  incoming_.Clear();
  StartRead(&incoming_);
  if (to_write != nullptr) StartWrite(to_write);
}

void LoadStream::RecordLocked(const v1::ControlResponse& response, Clock::time_point now) {
  const auto it = outstanding_.find(response.sequence());
  if (it == outstanding_.end()) return;
  const auto [scheduled, sent] = it->second;
  outstanding_.erase(it);
  if (response.error_code() == 0 && response.result().status() != v1::SOLVE_STATUS_SUPERSEDED) ++answered_;
  if (!Counted(scheduled)) return;  // warm-up or after the window
  if (response.error_code() != 0) {
    ++tally_.errors[CodeName(response.error_code())];
  } else if (response.result().status() == v1::SOLVE_STATUS_SUPERSEDED) {
    ++tally_.superseded;
  } else {
    tally_.latency_ms.push_back(std::chrono::duration<double, std::milli>(now - scheduled).count());
    tally_.service_ms.push_back(std::chrono::duration<double, std::milli>(now - sent).count());
    tally_.solve_ms.push_back(response.result().solve_ms());
    tally_.iterations += response.result().iterations();
    if (!response.result().has_plan()) ++tally_.no_plan;
  }
}

void LoadStream::Stop(std::chrono::milliseconds drain) {
  bool writes_done = false;
  {
    std::unique_lock<std::mutex> lock(mu_);
    stopping_ = true;
    changed_.wait_for(lock, drain, [&] { return outstanding_.empty() || done_; });
    if (!done_ && !writing_ && !writes_done_sent_) writes_done = writes_done_sent_ = true;
  }
  if (writes_done) StartWritesDone();
  std::unique_lock<std::mutex> lock(mu_);
  if (!changed_.wait_for(lock, drain, [&] { return done_; })) {
    lock.unlock();
    context_.TryCancel();
    lock.lock();
    changed_.wait(lock, [&] { return done_; });
  }
}

void LoadStream::OnDone(const grpc::Status& status) {
  std::lock_guard<std::mutex> lock(mu_);
  done_ = true;
  final_status_ = status;
  if (!status.ok() && !stopping_) ++tally_.errors[CodeName(status.error_code())];
  changed_.notify_all();
}

std::uint64_t LoadStream::answered() const {
  std::lock_guard<std::mutex> lock(mu_);
  return answered_;
}

StreamTally LoadStream::TakeTally() {
  std::lock_guard<std::mutex> lock(mu_);
  return std::move(tally_);
}

}  // namespace nupmpc::loadtest
