// --log_format and what the server logs: JSON lines that parse, with the session and
// principal of the line as fields; access lines per RPC at debug only; session lifecycle at
// info; slow solves at warn with dimensions and iterations; nothing per solve at info.
#include "server/observability/log_format.h"

#include <fstream>
#include <sstream>

#include "absl/strings/str_split.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "server/observability/log_context.h"
#include "spdlog/sinks/ostream_sink.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {
namespace {

// The default logger writes to a string while the capture lives.
class LogCapture {
 public:
  LogCapture(absl::string_view format, spdlog::level::level_enum level) : previous_(spdlog::default_logger()) {
    auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out_);
    auto logger = std::make_shared<spdlog::logger>("capture", sink);
    auto formatter = server::MakeLogFormatter(format);
    EXPECT_TRUE(formatter.ok());
    logger->set_formatter(*std::move(formatter));
    logger->set_level(level);
    spdlog::set_default_logger(logger);
  }
  ~LogCapture() { spdlog::set_default_logger(previous_); }
  std::vector<std::string> Lines() const { return absl::StrSplit(out_.str(), '\n', absl::SkipEmpty()); }

 private:
  std::ostringstream out_;
  std::shared_ptr<spdlog::logger> previous_;
};

TEST(LogFormat, JsonLinesParseAndCarryTheSessionAndPrincipal) {
  LogCapture capture("json", spdlog::level::info);
  {
    const server::LogContext context("3f2a", "alice \"the\" operator");
    spdlog::info("a \"quoted\" message\nwith a newline and a tab\t and \x01");
  }
  spdlog::warn("no context");
  const std::vector<std::string> lines = capture.Lines();
  ASSERT_EQ(lines.size(), 2u);
  const nlohmann::json first = nlohmann::json::parse(lines[0]);
  EXPECT_EQ(first["level"], "info");
  EXPECT_EQ(first["msg"], "a \"quoted\" message\nwith a newline and a tab\t and \x01");
  EXPECT_EQ(first["session"], "3f2a");
  EXPECT_EQ(first["principal"], "alice \"the\" operator");
  const std::string time = first["time"];
  EXPECT_EQ(time.size(), std::string("2026-12-03T13:47:34.289123Z").size()) << time;
  EXPECT_EQ(time.back(), 'Z');
  const nlohmann::json second = nlohmann::json::parse(lines[1]);
  EXPECT_EQ(second["level"], "warning");
  EXPECT_FALSE(second.contains("session"));
}

TEST(LogFormat, TextLinesEndWithTheContext) {
  LogCapture capture("text", spdlog::level::info);
  {
    const server::LogContext context("3f2a", "");
    spdlog::info("created");
  }
  const std::vector<std::string> lines = capture.Lines();
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_NE(lines[0].find("[info] created session=3f2a"), std::string::npos) << lines[0];
  EXPECT_EQ(lines[0].find("principal="), std::string::npos) << lines[0];
  EXPECT_FALSE(server::MakeLogFormatter("xml").ok());
}

class ServerLogTest : public ::testing::Test {
 protected:
  void Start(const server::ServerOptions& options) {
    auto s = server::GrpcServer::Start(options);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
    target_ = "127.0.0.1:" + std::to_string(server_->port());
  }
  void TearDown() override {
    if (server_ != nullptr) server_->Shutdown();
  }
  static server::ServerOptions Options() {
    server::ServerOptions o;
    o.address = "127.0.0.1:0";
    o.grace_period_s = 1.0;
    return o;
  }
  std::unique_ptr<server::GrpcServer> server_;
  std::string target_;
};

std::vector<nlohmann::json> Parsed(const std::vector<std::string>& lines) {
  std::vector<nlohmann::json> out;
  for (const std::string& line : lines) out.push_back(nlohmann::json::parse(line));
  return out;
}

TEST_F(ServerLogTest, AccessLinesAtDebugSessionEventsAtInfoSlowSolvesAtWarn) {
  const std::string tokens = ::testing::TempDir() + "/log-tokens-" + std::to_string(::getpid());
  std::ofstream(tokens) << "alice-0123456789abcdef alice\n";
  server::ServerOptions o = Options();
  o.auth_tokens_file = tokens;
  o.slow_solve_ms = 1e-9;  // every solve is slow
  const bench::BenchmarkInstance inst = LoadInstanceOrDie("masses_N30");
  std::vector<nlohmann::json> lines;
  {
    LogCapture capture("json", spdlog::level::debug);
    Start(o);
    ChannelSecurity alice;
    alice.token = "alice-0123456789abcdef";
    auto client = Client::Connect(target_, alice);
    ASSERT_TRUE(client.ok());
    auto created = (*client)->CreateSession(SpecOrDie(inst.problem));
    ASSERT_TRUE(created.ok());
    v1::Step step;
    step.mutable_state()->Add(inst.closed_loop->x1[0].data(),
                              inst.closed_loop->x1[0].data() + inst.closed_loop->x1[0].size());
    ASSERT_TRUE((*client)->Solve(created->session_id(), step).ok());
    ASSERT_TRUE((*client)->CloseSession(created->session_id()).ok());
    server_->Shutdown();
    server_.reset();
    lines = Parsed(capture.Lines());
    const std::string id = created->session_id();
    const auto count = [&](const std::string& level, const std::string& text) {
      int n = 0;
      for (const nlohmann::json& line : lines) {
        if (line["level"] == level && line["msg"].get<std::string>().find(text) != std::string::npos) {
          EXPECT_EQ(line.value("session", ""), id) << line.dump();
          EXPECT_EQ(line.value("principal", ""), "alice") << line.dump();
          ++n;
        }
      }
      return n;
    };
    EXPECT_EQ(count("debug", "access: CreateSession OK"), 1);
    EXPECT_EQ(count("debug", "access: Solve OK"), 1);
    EXPECT_EQ(count("debug", "access: CloseSession OK"), 1);
    EXPECT_EQ(count("info", "created"), 1);
    EXPECT_EQ(count("info", "closed"), 1);
    EXPECT_EQ(count("warning", "slow solve"), 1);
    for (const nlohmann::json& line : lines) {
      if (line["level"] != "warning" || line["msg"].get<std::string>().find("slow solve") == std::string::npos)
        continue;
      EXPECT_NE(line["msg"].get<std::string>().find("M=12 L=3 K=12 N=30"), std::string::npos) << line.dump();
      EXPECT_NE(line["msg"].get<std::string>().find("iterations"), std::string::npos) << line.dump();
    }
  }

  // At info: nothing per solve or per call.
  o.slow_solve_ms = 0.0;
  LogCapture capture("json", spdlog::level::info);
  Start(o);
  ChannelSecurity alice;
  alice.token = "alice-0123456789abcdef";
  auto client = Client::Connect(target_, alice);
  ASSERT_TRUE(client.ok());
  auto session = (*client)->OpenSession(SpecOrDie(inst.problem));
  ASSERT_TRUE(session.ok());
  for (int k = 0; k < 20; ++k) {
    v1::Step step;
    const Eigen::VectorXd& x = inst.closed_loop->x1[k % inst.closed_loop->x1.size()];
    step.mutable_state()->Add(x.data(), x.data() + x.size());
    ASSERT_TRUE((*session)->Step(step).ok());
  }
  ASSERT_TRUE((*session)->Close().ok());
  server_->Shutdown();
  server_.reset();
  const std::vector<nlohmann::json> info_lines = Parsed(capture.Lines());
  int session_lines = 0;
  for (const nlohmann::json& line : info_lines) {
    EXPECT_NE(line["level"], "debug") << line.dump();
    if (line.contains("session")) ++session_lines;
  }
  EXPECT_EQ(session_lines, 2) << "created and closed, nothing for the 20 steps";
  std::filesystem::remove(tokens);
}

}  // namespace
}  // namespace nupmpc::testing
