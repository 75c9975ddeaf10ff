// The operators' HTTP endpoint of a running server: after a known sequence of solves and
// errors, /metrics parses as Prometheus text and every counter and histogram count is
// what was done, the same figures GetServerInfo reports; label sets stay bounded however
// many sessions exist; /readyz follows the health service.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "gtest/gtest.h"
#include "tests/server/service/service_fixture.h"
#include "tests/util/prometheus_parse.h"
// Last: it includes <resolv.h>, whose macro _res would rewrite a parameter of Eigen's.
#include "httplib.h"

namespace nupmpc::testing {
namespace {

// Prometheus' own linter (package prometheus, which deploy/install-deps.sh installs): a
// missing promtool fails the test rather than passing it unchecked.
void CheckWithPromtool(const std::string& body) {
  ASSERT_EQ(access("/usr/bin/promtool", X_OK), 0) << "/usr/bin/promtool is missing (package prometheus; "
                                                     "deploy/install-deps.sh installs it)";
  const std::string path = ::testing::TempDir() + "/metrics." + std::to_string(getpid()) + ".txt";
  {
    std::ofstream file(path);
    file << body;
  }
  const std::string command = "/usr/bin/promtool check metrics < " + path + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  char buffer[512];
  while (fgets(buffer, sizeof buffer, pipe) != nullptr) output += buffer;
  const int status = pclose(pipe);
  std::remove(path.c_str());
  EXPECT_EQ(status, 0) << "promtool check metrics:\n" << output;
}

class MetricsEndpointTest : public ServiceTest {
 protected:
  void SetUp() override {
    spdlog::set_level(spdlog::level::warn);
    server::ServerOptions options = DefaultOptions();
    options.metrics_address = "127.0.0.1:0";
    options.max_sessions = 20000;
    StartServer(options);
    ASSERT_GT(server_->metrics_port(), 0);
  }
  httplib::Result Get(const std::string& path) {
    httplib::Client http("127.0.0.1", server_->metrics_port());
    return http.Get(path);
  }
  ParsedMetrics Scrape() {
    httplib::Result res = Get("/metrics");
    EXPECT_TRUE(res) << "GET /metrics failed";
    if (!res) return {};
    EXPECT_EQ(res->status, 200);
    EXPECT_EQ(res->get_header_value("Content-Type"), "text/plain; version=0.0.4; charset=utf-8");
    absl::StatusOr<ParsedMetrics> parsed = ParsePrometheusText(res->body);
    EXPECT_TRUE(parsed.ok()) << parsed.status() << "\n" << res->body;
    CheckWithPromtool(res->body);
    return parsed.ok() ? *std::move(parsed) : ParsedMetrics{};
  }
};

v1::Step StepFrom(const Eigen::VectorXd& x) {
  v1::Step step;
  step.mutable_state()->Add(x.data(), x.data() + x.size());
  return step;
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

TEST_F(MetricsEndpointTest, CountersAndHistogramsAreWhatWasDone) {
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  const v1::ProblemSpec spec = SpecOrDie(inst.problem);
  const std::vector<Eigen::VectorXd>& states = inst.closed_loop->x1;
  std::vector<v1::SolveResult> results;

  auto created = client_->CreateSession(spec);
  ASSERT_TRUE(created.ok()) << created.status();
  for (int t = 0; t < 5; ++t) {
    auto r = client_->Solve(created->session_id(), StepFrom(states[static_cast<std::size_t>(t)]));
    ASSERT_TRUE(r.ok()) << r.status();
    results.push_back(*r);
  }
  v1::Step wrong_size;
  wrong_size.add_state(1.0);
  const absl::Status bad_step = client_->Solve(created->session_id(), wrong_size).status();
  ASSERT_FALSE(bad_step.ok());
  ASSERT_EQ(client_->Solve(std::string(32, '0'), StepFrom(states[0])).status().code(), absl::StatusCode::kNotFound);
  {
    auto stream = client_->OpenSession(spec);
    ASSERT_TRUE(stream.ok()) << stream.status();
    for (int t = 0; t < 3; ++t) {
      auto r = (*stream)->Step(StepFrom(states[static_cast<std::size_t>(t)]));
      ASSERT_TRUE(r.ok()) << r.status();
      results.push_back(*r);
    }
    ASSERT_TRUE((*stream)->Close().ok());
  }
  auto once = client_->SolveOnce(spec);
  ASSERT_TRUE(once.ok()) << once.status();
  results.push_back(*once);

  const ParsedMetrics m = Scrape();
  double solves = 0.0;
  for (const auto& [key, value] : m.samples) {
    if (key.rfind("nupmpc_solves_total{", 0) == 0) solves += value;
  }
  EXPECT_EQ(solves, 9);
  double iterations = 0.0, solve_seconds = 0.0;
  for (const v1::SolveResult& r : results) {
    ASSERT_EQ(r.status(), v1::SOLVE_STATUS_CONVERGED);
    ASSERT_EQ(r.algorithm(), results[0].algorithm());
    iterations += r.iterations();
    solve_seconds += r.solve_ms() / 1000.0;
  }
  const std::string algorithm =
      Lower(v1::Algorithm_Name(results[0].algorithm()).substr(std::string("ALGORITHM_").size()));
  EXPECT_EQ(m.at("nupmpc_solves_total{status=\"converged\",algorithm=\"" + algorithm + "\"}"), 9);
  for (const char* h : {"nupmpc_solve_duration_seconds", "nupmpc_queue_wait_seconds", "nupmpc_step_latency_seconds",
                        "nupmpc_solve_iterations"}) {
    EXPECT_EQ(m.at(std::string(h) + "_count"), 9) << h;
  }
  EXPECT_EQ(m.at("nupmpc_solve_iterations_sum"), iterations);
  EXPECT_NEAR(m.at("nupmpc_solve_duration_seconds_sum"), solve_seconds, 1e-9 * std::max(1.0, solve_seconds));
  // The end-to-end latency includes the solve.
  EXPECT_GE(m.at("nupmpc_step_latency_seconds_sum"), solve_seconds * (1 - 1e-9));

  const std::string bad_code = absl::StatusCodeToString(bad_step.code());
  EXPECT_EQ(m.at("nupmpc_rpc_errors_total{method=\"Solve\",code=\"NOT_FOUND\"}"), 1);
  EXPECT_EQ(m.at("nupmpc_rpc_errors_total{method=\"Solve\",code=\"" + bad_code + "\"}"), 1);
  EXPECT_EQ(m.at("nupmpc_sessions_created_total"), 2);  // CreateSession and the stream's
  EXPECT_EQ(m.at("nupmpc_sessions_closed_total"), 1);   // the stream's, with the stream
  EXPECT_EQ(m.at("nupmpc_active_sessions"), 1);
  EXPECT_EQ(m.at("nupmpc_workers"), 2);
  EXPECT_EQ(m.at("nupmpc_solver_cores"), 2);
  EXPECT_GT(m.at("nupmpc_worker_busy_seconds_total"), 0);
  EXPECT_GT(m.at("nupmpc_process_resident_memory_bytes"), 0);
  EXPECT_GT(m.at("nupmpc_process_open_fds"), 0);
  EXPECT_EQ(m.at("nupmpc_draining"), 0);
  EXPECT_EQ(m.types.at("nupmpc_build_info"), "gauge");

  // GetServerInfo reads the same counters.
  auto info = client_->GetServerInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->solves(), 9u);
  EXPECT_EQ(info->errors_by_code().at("NOT_FOUND"), 1u);
  EXPECT_EQ(info->errors_by_code().at(bad_code), 1u);
  std::uint64_t in_buckets = 0;
  for (const v1::LatencyBucket& b : info->solve_latency()) in_buckets += b.count();
  EXPECT_EQ(in_buckets, 9u);
}

TEST_F(MetricsEndpointTest, LabelSetsStayBoundedWithTenThousandSessions) {
  core::Problem p = core::Problem::TimeInvariant(1, 1, 1, 3);
  p.A = {Eigen::MatrixXd::Constant(1, 1, 0.9)};
  p.B = {Eigen::MatrixXd::Ones(1, 1)};
  p.C = {Eigen::MatrixXd::Ones(1, 1)};
  p.initial_mean = Eigen::VectorXd::Ones(1);
  for (int n = 0; n < p.horizon; ++n) {
    p.mutable_input_prior(n, 0) = core::ScalarPrior::Gaussian(0.0, 1.0);
    p.mutable_output_prior(n + 1, 0) = core::ScalarPrior::Gaussian(0.0, 1.0);
  }
  const v1::ProblemSpec tiny = SpecOrDie(p);
  ASSERT_TRUE(client_->CreateSession(tiny).ok());
  const std::size_t series_with_one = Scrape().samples.size();
  for (int i = 1; i < 10000; ++i) ASSERT_TRUE(client_->CreateSession(tiny).ok()) << i;
  const ParsedMetrics m = Scrape();
  EXPECT_EQ(m.at("nupmpc_active_sessions"), 10000);
  EXPECT_EQ(m.samples.size(), series_with_one);
  const std::regex session_id("[0-9a-f]{32}");
  for (const auto& [key, value] : m.samples) EXPECT_FALSE(std::regex_search(key, session_id)) << key;
}

TEST_F(MetricsEndpointTest, ReadyzFollowsTheHealthServiceAndHealthzTheProcess) {
  httplib::Result ready = Get("/readyz");
  ASSERT_TRUE(ready);
  EXPECT_EQ(ready->status, 200);
  server_->ReportNotServing();
  ready = Get("/readyz");
  ASSERT_TRUE(ready);
  EXPECT_EQ(ready->status, 503);
  httplib::Result healthy = Get("/healthz");
  ASSERT_TRUE(healthy);
  EXPECT_EQ(healthy->status, 200);
  EXPECT_EQ(Scrape().at("nupmpc_draining"), 1);
}

}  // namespace
}  // namespace nupmpc::testing
