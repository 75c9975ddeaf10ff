#include "server/rpc/fleet_call.h"

#include <algorithm>
#include <atomic>
#include <memory>
#include <vector>

#include "absl/strings/str_cat.h"

namespace nupmpc::server {
namespace {

// One SolveFleet call in flight, shared by its runner tasks and its steps' session tasks.
// The call (request, response) lives until it is answered, which the last step does.
class FleetRun : public std::enable_shared_from_this<FleetRun> {
 public:
  explicit FleetRun(FleetCall* call)
      : call_(call),
        state_(call->state()),
        request_(call->request()),
        response_(call->response()),
        steps_(static_cast<std::size_t>(call->request().steps_size())),
        context_(call->Context()) {}

  void Start(const Caller& caller) {
    if (state_->draining.load()) {
      call_->Reply(absl::UnavailableError("the server is shutting down"));
      return;
    }
    if (steps_ > static_cast<std::size_t>(state_->options.max_fleet_steps)) {
      call_->Reply(absl::InvalidArgumentError(absl::StrCat(
          "steps: ", steps_, " steps, over ServerLimits.max_fleet_steps = ", state_->options.max_fleet_steps,
          "; split the fleet")));
      return;
    }
    items_.resize(steps_);
    for (const v1::SolveRequest& step : request_.steps()) response_->add_answers()->set_session_id(step.session_id());
    // One count per step plus one held here, so that no step can answer the call while
    // this loop still reads it.
    remaining_.store(steps_ + 1);
    std::size_t accepted = 0;
    double expected_ms = 0.0;
    for (std::size_t i = 0; i < steps_; ++i) {
      absl::StatusOr<std::shared_ptr<SessionEntry>> entry =
          state_->registry.Find(request_.steps(i).session_id(), caller);
      if (entry.ok()) {
        if (absl::Status refused = (*entry)->UnaryStepsRefused(); !refused.ok()) entry = std::move(refused);
      }
      if (!entry.ok()) {
        AnswerError(i, entry.status());
        continue;
      }
      items_[i].entry = *std::move(entry);
      items_[i].ticket = items_[i].entry->fleet_steps_accepted.fetch_add(1) + 1;
      expected_ms += std::max(0.0, items_[i].entry->last_solve_ms.load(std::memory_order_relaxed));
      ++accepted;
    }
    const int runners = static_cast<int>(std::min<std::size_t>(accepted, state_->pool.threads()));
    int started = 0;
    absl::Status refused;
    for (int r = 0; r < runners; ++r) {
      refused = state_->pool.TrySubmit([self = shared_from_this()] { self->RunSteps(); }, expected_ms / runners);
      if (!refused.ok()) break;
      ++started;
    }
    if (runners > 0 && started == 0) {  // nothing of it can run: every accepted step gets the pool's answer
      for (std::size_t i = next_.exchange(steps_); i < steps_; ++i) {
        if (items_[i].entry != nullptr) AnswerError(i, refused);
      }
    }
    Done();
  }

 private:
  struct Item {
    std::shared_ptr<SessionEntry> entry;  ///< null: answered with an error when the call came
    std::uint64_t ticket = 0;             ///< the session's fleet step number (see the header)
  };

  // A runner: takes the call's steps one after another until none is left.
  void RunSteps() {
    for (std::size_t i = next_.fetch_add(1); i < steps_; i = next_.fetch_add(1)) {
      if (items_[i].entry != nullptr) StartStep(i);
    }
  }

  void StartStep(std::size_t i) {
    const std::shared_ptr<SessionEntry>& entry = items_[i].entry;
    // A newer step of the session (later in this call, or in a later call) was accepted:
    // this one takes no place in the session's queue.
    if (Superseded(i)) return AnswerSuperseded(i);
    auto solve = [self = shared_from_this(), i] { self->SolveOne(i); };
    // This runner holds a core already: an idle session's step is solved right here.
    if (SessionStrand::RunNowIfIdle(entry->strand, state_->pool, solve)) return;
    const absl::Status queued = SessionStrand::Submit(
        entry->strand, state_->pool,
        {.run = solve,
         .fail = [self = shared_from_this(), i](const absl::Status& refused) { self->AnswerError(i, refused); },
         .expected_ms = entry->last_solve_ms.load(std::memory_order_relaxed),
         .due = StepDue(entry->timing, request_.steps(static_cast<int>(i)).step(), *context_.received_at),
         .superseded = [self = shared_from_this(), i] { return self->Superseded(i); },
         .answer_superseded = [self = shared_from_this(), i] { self->AnswerSuperseded(i); }});
    if (!queued.ok()) AnswerError(i, queued);
  }

  bool Superseded(std::size_t i) const { return items_[i].ticket < items_[i].entry->fleet_steps_accepted.load(); }

  // Nothing of the step is applied: a newer step of its session follows.
  void AnswerSuperseded(std::size_t i) {
    response_->mutable_answers(static_cast<int>(i))->mutable_result()->set_status(v1::SOLVE_STATUS_SUPERSEDED);
    Done();
  }

  // Runs as a task of the step's session (its strand).
  void SolveOne(std::size_t i) {
    Item& item = items_[i];
    v1::FleetAnswer* answer = response_->mutable_answers(static_cast<int>(i));
    if (Superseded(i)) return AnswerSuperseded(i);
    const auto started_at = Clock::now();
    const absl::Status status = RunCatchingExceptions("SolveFleet", [&] {
      return SolveStep(*item.entry, request_.steps(static_cast<int>(i)).step(), context_, answer->mutable_result());
    });
    if (!status.ok()) {
      answer->clear_result();
      AnswerError(i, status);
      return;
    }
    state_->RecordSolve(answer->result(), item.entry.get(),
                        std::chrono::duration<double>(started_at - queued_at_).count(),
                        std::chrono::duration<double>(Clock::now() - queued_at_).count());
    Done();
  }

  void AnswerError(std::size_t i, const absl::Status& status) {
    v1::FleetAnswer* answer = response_->mutable_answers(static_cast<int>(i));
    // Counted like any RPC error; the code and the field path go to the client in the answer.
    const grpc::Status counted = state_->ToGrpc(Rpc::kSolveFleet, status);
    answer->set_error_code(counted.error_code());
    answer->set_error_message(absl::StrCat("steps[", i, "].", counted.error_message()));
    Done();
  }

  // One step answered (or the start's hold released); the last one answers the call.
  void Done() {
    if (remaining_.fetch_sub(1, std::memory_order_acq_rel) == 1) call_->Reply(absl::OkStatus());
  }

  FleetCall* const call_;
  ServerState* const state_;
  const v1::SolveFleetRequest& request_;
  v1::SolveFleetResponse* const response_;  ///< each step writes only its own answer
  const std::size_t steps_;
  const CallContext context_;
  const Clock::time_point queued_at_ = Clock::now();
  std::vector<Item> items_;
  std::atomic<std::size_t> next_{0};  ///< the next step a runner takes
  std::atomic<std::size_t> remaining_{0};
};

}  // namespace

void StartFleet(FleetCall* call, const Caller& caller) { std::make_shared<FleetRun>(call)->Start(caller); }

}  // namespace nupmpc::server
