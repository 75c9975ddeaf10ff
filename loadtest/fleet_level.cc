#include "loadtest/fleet_level.h"

#include <algorithm>
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "loadtest/quantile.h"

namespace nupmpc::loadtest {

namespace {

using Clock = std::chrono::steady_clock;

// One caller of the level: its own connection and share of the sessions, one call after
// another, each session cycling through the closed-loop states from its own offset.
struct FleetSlice {
  std::unique_ptr<Client> client;
  int first_session = 0;  ///< the level's index of the slice's first session
  std::vector<std::string> ids;
};

absl::StatusOr<FleetSlice> OpenSlice(const std::string& target, const ChannelSecurity& security, const StreamPlan& plan,
                                     int first_session, int sessions) {
  absl::StatusOr<std::unique_ptr<Client>> connected = Client::Connect(target, security, std::chrono::seconds(30));
  if (!connected.ok()) return connected.status();
  FleetSlice slice{.client = *std::move(connected), .first_session = first_session, .ids = {}};
  for (int s = 0; s < sessions; ++s) {
    absl::StatusOr<v1::CreateSessionResponse> created = slice.client->CreateSession(*plan.spec);
    if (!created.ok()) return created.status();
    slice.ids.push_back(created->session_id());
  }
  return slice;
}

// The slice's calls until `end`; those sent from `measure_from` on are counted.
absl::StatusOr<FleetReport> StepSlice(FleetSlice& slice, const StreamPlan& plan, Clock::time_point measure_from,
                                      Clock::time_point end) {
  const std::vector<std::vector<double>>& states = *plan.states;
  v1::SolveFleetRequest request;
  for (const std::string& id : slice.ids) {
    v1::SolveRequest* step = request.add_steps();
    step->set_session_id(id);
    step->mutable_step()->mutable_state()->Resize(static_cast<int>(states[0].size()), 0.0);
  }
  FleetReport report;
  report.sessions = static_cast<int>(slice.ids.size());
  Clock::time_point last_answer = measure_from;
  for (std::size_t period = 0;; ++period) {
    const Clock::time_point sent = Clock::now();
    if (sent >= end) break;
    for (int s = 0; s < request.steps_size(); ++s) {
      const std::size_t offset = 7 * static_cast<std::size_t>(slice.first_session + s);
      const std::vector<double>& x = states[(period + offset) % states.size()];
      std::copy(x.begin(), x.end(), request.mutable_steps(s)->mutable_step()->mutable_state()->begin());
    }
    absl::StatusOr<v1::SolveFleetResponse> response = slice.client->SolveFleet(request);
    if (!response.ok()) return response.status();
    if (sent < measure_from) continue;
    last_answer = Clock::now();
    report.call_ms.push_back(std::chrono::duration<double, std::milli>(last_answer - sent).count());
    ++report.calls;
    for (const v1::FleetAnswer& a : response->answers()) {
      if (a.error_code() != 0) {
        ++report.step_errors;
      } else {
        ++report.answered;
        if (a.result().status() != v1::SOLVE_STATUS_SUPERSEDED) {
          ++report.solved;
          report.iterations += a.result().iterations();
        }
      }
    }
  }
  report.measured_s = std::max(1e-9, std::chrono::duration<double>(last_answer - measure_from).count());
  return report;
}

// Quantiles, the rate and the mean iterations of a report whose counts are summed.
void Summarise(FleetReport& report) {
  if (report.measured_s > 0.0) report.steps_per_s = static_cast<double>(report.answered) / report.measured_s;
  if (report.solved > 0)
    report.mean_iterations = static_cast<double>(report.iterations) / static_cast<double>(report.solved);
  report.call_p50_ms = Quantile(report.call_ms, 0.5);
  report.call_p99_ms = Quantile(report.call_ms, 0.99);
}

// Counts of `from` added to `into` (measured time not touched).
void AddCounts(const FleetReport& from, FleetReport& into) {
  into.calls += from.calls;
  into.answered += from.answered;
  into.solved += from.solved;
  into.step_errors += from.step_errors;
  into.iterations += from.iterations;
  into.call_ms.insert(into.call_ms.end(), from.call_ms.begin(), from.call_ms.end());
}

}  // namespace

absl::StatusOr<FleetReport> RunFleetLevel(const std::string& target, const ChannelSecurity& security,
                                          const StreamPlan& plan, int sessions, int calls_in_flight, double duration_s,
                                          double warmup_s) {
  if (calls_in_flight < 1 || calls_in_flight > sessions) {
    return absl::InvalidArgumentError(
        absl::StrCat("calls in flight: ", calls_in_flight, ", not within 1 to the ", sessions, " sessions"));
  }
  std::vector<FleetSlice> slices;
  absl::Status failed;
  for (int k = 0; k < calls_in_flight && failed.ok(); ++k) {
    const int first = sessions * k / calls_in_flight, next = sessions * (k + 1) / calls_in_flight;
    absl::StatusOr<FleetSlice> slice = OpenSlice(target, security, plan, first, next - first);
    if (slice.ok()) {
      slices.push_back(*std::move(slice));
    } else {
      failed = slice.status();
    }
  }
  std::vector<absl::StatusOr<FleetReport>> stepped(slices.size(), absl::UnknownError("not run"));
  if (failed.ok()) {
    const Clock::time_point measure_from =
        Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(warmup_s));
    const Clock::time_point end =
        measure_from + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(duration_s));
    std::vector<std::thread> callers;
    for (std::size_t k = 0; k < slices.size(); ++k) {
      callers.emplace_back([&, k] { stepped[k] = StepSlice(slices[k], plan, measure_from, end); });
    }
    for (std::thread& caller : callers) caller.join();
  }
  for (FleetSlice& slice : slices) {
    for (const std::string& id : slice.ids) (void)slice.client->CloseSession(id);
  }
  if (!failed.ok()) return failed;
  FleetReport report;
  report.sessions = sessions;
  report.calls_in_flight = calls_in_flight;
  for (const absl::StatusOr<FleetReport>& slice : stepped) {
    if (!slice.ok()) return slice.status();
    AddCounts(*slice, report);
    // The callers ran at once: the longest of their windows, so that the rate is never
    // overstated by a caller whose last answer came early.
    report.measured_s = std::max(report.measured_s, slice->measured_s);
  }
  Summarise(report);
  return report;
}

FleetReport MergeFleetRounds(const std::vector<FleetReport>& rounds) {
  FleetReport merged;
  for (const FleetReport& round : rounds) {
    merged.sessions = round.sessions;
    merged.calls_in_flight = round.calls_in_flight;
    merged.measured_s += round.measured_s;
    AddCounts(round, merged);
  }
  Summarise(merged);
  return merged;
}

}  // namespace nupmpc::loadtest
