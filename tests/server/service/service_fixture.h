#ifndef NUPMPC_TESTS_SERVER_SERVICE_FIXTURE_H_
#define NUPMPC_TESTS_SERVER_SERVICE_FIXTURE_H_

// An in-process nupmpc server on a loopback port plus a client, and the benchmark
// instances as ProblemSpecs.

#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "gtest/gtest.h"
#include "loadtest/instances/benchmark_instance.h"
#include "loadtest/instances/spec_from_problem.h"
#include "server/convert/spec_conversion.h"
#include "server/grpc_server.h"
#include "spdlog/spdlog.h"
#include "tests/util/benchmark_files.h"

namespace nupmpc::testing {

inline v1::ProblemSpec SpecOrDie(const core::Problem& problem) {
  absl::StatusOr<v1::ProblemSpec> spec = bench::SpecFromProblem(problem);
  EXPECT_TRUE(spec.ok()) << spec.status();
  return *std::move(spec);
}

class ServiceTest : public ::testing::Test {
 protected:
  static server::ServerOptions DefaultOptions() {
    server::ServerOptions o;
    o.address = "127.0.0.1:0";
    o.max_message_bytes = 64 << 20;
    o.grace_period_s = 1.0;
    return o;
  }
  void StartServer(const server::ServerOptions& options) {
    absl::StatusOr<std::unique_ptr<server::GrpcServer>> s = server::GrpcServer::Start(options);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
    target_ = "127.0.0.1:" + std::to_string(server_->port());
    client_ = std::make_unique<Client>(target_);
  }
  void SetUp() override {
    spdlog::set_level(spdlog::level::warn);  // session lifecycle logs would drown the test output
    StartServer(DefaultOptions());
  }
  void TearDown() override {
    client_.reset();
    if (server_ != nullptr) server_->Shutdown();
  }

  std::unique_ptr<server::GrpcServer> server_;
  std::string target_;
  std::unique_ptr<Client> client_;
};

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_SERVER_SERVICE_FIXTURE_H_
