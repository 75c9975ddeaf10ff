#include "loadtest/fleet_level.h"

#include <algorithm>
#include <chrono>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "loadtest/core_baseline.h"

namespace nupmpc::loadtest {

absl::StatusOr<FleetReport> RunFleetLevel(const std::string& target, const ChannelSecurity& security,
                                          const StreamPlan& plan, int sessions, double duration_s, double warmup_s) {
  absl::StatusOr<std::unique_ptr<Client>> connected = Client::Connect(target, security, std::chrono::seconds(30));
  if (!connected.ok()) return connected.status();
  Client& client = **connected;
  const std::vector<std::vector<double>>& states = *plan.states;
  std::vector<std::string> ids;
  for (int s = 0; s < sessions; ++s) {
    absl::StatusOr<v1::CreateSessionResponse> created = client.CreateSession(*plan.spec);
    if (!created.ok()) return created.status();
    ids.push_back(created->session_id());
  }
  v1::SolveFleetRequest request;
  for (int s = 0; s < sessions; ++s) {
    v1::SolveRequest* step = request.add_steps();
    step->set_session_id(ids[s]);
    step->mutable_step()->mutable_state()->Resize(static_cast<int>(states[0].size()), 0.0);
  }
  using Clock = std::chrono::steady_clock;
  const Clock::time_point measure_from = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                                            std::chrono::duration<double>(warmup_s));
  const Clock::time_point end = measure_from + std::chrono::duration_cast<Clock::duration>(
                                                   std::chrono::duration<double>(duration_s));
  FleetReport report;
  report.sessions = sessions;
  absl::Status failed;
  Clock::time_point last_answer = measure_from;
  for (std::size_t period = 0;; ++period) {
    const Clock::time_point sent = Clock::now();
    if (sent >= end) break;
    for (int s = 0; s < sessions; ++s) {
      const std::vector<double>& x = states[(period + 7 * static_cast<std::size_t>(s)) % states.size()];
      std::copy(x.begin(), x.end(), request.mutable_steps(s)->mutable_step()->mutable_state()->begin());
    }
    absl::StatusOr<v1::SolveFleetResponse> response = client.SolveFleet(request);
    if (!response.ok()) {
      failed = response.status();
      break;
    }
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
  for (const std::string& id : ids) (void)client.CloseSession(id);
  if (!failed.ok()) return failed;
  report.measured_s = std::max(1e-9, std::chrono::duration<double>(last_answer - measure_from).count());
  report.steps_per_s = static_cast<double>(report.answered) / report.measured_s;
  report.mean_iterations =
      report.solved > 0 ? static_cast<double>(report.iterations) / static_cast<double>(report.solved) : 0.0;
  report.call_p50_ms = Quantile(report.call_ms, 0.5);
  report.call_p99_ms = Quantile(report.call_ms, 0.99);
  return report;
}

FleetReport MergeFleetRounds(const std::vector<FleetReport>& rounds) {
  FleetReport merged;
  for (const FleetReport& round : rounds) {
    merged.sessions = round.sessions;
    merged.measured_s += round.measured_s;
    merged.calls += round.calls;
    merged.answered += round.answered;
    merged.solved += round.solved;
    merged.step_errors += round.step_errors;
    merged.iterations += round.iterations;
    merged.call_ms.insert(merged.call_ms.end(), round.call_ms.begin(), round.call_ms.end());
  }
  if (merged.measured_s > 0.0) merged.steps_per_s = static_cast<double>(merged.answered) / merged.measured_s;
  if (merged.solved > 0) merged.mean_iterations = static_cast<double>(merged.iterations) / static_cast<double>(merged.solved);
  merged.call_p50_ms = Quantile(merged.call_ms, 0.5);
  merged.call_p99_ms = Quantile(merged.call_ms, 0.99);
  return merged;
}

}  // namespace nupmpc::loadtest
