#ifndef NUPMPC_TESTS_SERVER_HOSTILE_CATALOGUE_H_
#define NUPMPC_TESTS_SERVER_HOSTILE_CATALOGUE_H_

// The hostile-input catalogue's harness: a server with a healthy session on
// masses_N30, and what every case of the catalogue ends with: the refusal has its code and
// names the field (or the rule), the healthy session still answers with the bit-identical
// plan, and the server's resident memory has not jumped. Also the raw-bytes calls that
// reach the server past the generated stubs.

#include <cstdint>
#include <memory>
#include <string>

#include "grpcpp/generic/generic_stub.h"
#include "grpcpp/grpcpp.h"
#include "tests/server/service/service_fixture.h"

namespace nupmpc::testing {

// A Control stream whose messages are bytes as they are (past the generated stub's
// serialisation), driven one operation at a time.
class RawControlStream {
 public:
  explicit RawControlStream(const std::string& target);
  ~RawControlStream();
  bool Write(const std::string& bytes);
  // The next answer's bytes; false when the stream ended.
  bool Read(std::string* bytes);
  // Half-closes and returns the status the stream ends with.
  grpc::Status Finish();

 private:
  bool Next();  // waits for the operation started last; whether it succeeded
  std::unique_ptr<grpc::GenericStub> stub_;
  grpc::CompletionQueue queue_;
  grpc::ClientContext context_;
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> stream_;
};

// A unary call of MpcService `method` whose request is `bytes` as they are; its status.
grpc::Status CallWithBytes(const std::string& target, const std::string& method, const std::string& bytes);
// Opens a Control stream, sends `bytes` as its first message and returns the status the
// stream ends with (expects no answer: the stream must end).
grpc::Status ControlWithBytes(const std::string& target, const std::string& bytes);

// A Control stream and its call's context (which must outlive it).
struct OpenStream {
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReaderWriter<v1::ControlRequest, v1::ControlResponse>> stream;
};

class HostileCatalogueTest : public ServiceTest {
 protected:
  void SetUp() override;
  // Starts the server anew with `options`; the client carries bearer `token` (empty: none).
  // The healthy session is created again on it.
  void RestartServer(server::ServerOptions options, const std::string& token = {});
  // masses_N30's closed-loop state at step t, solved from a cold start (so the plan does
  // not depend on what the session solved before).
  v1::Step StateStep(int t) const;
  std::uint64_t Rss();
  // What every case ends with: the healthy session answers as before, memory did not jump.
  void ExpectServerUnharmed();
  // Whether `result` is the healthy session's plan, bit for bit (a session of the same spec
  // solving StateStep(4) gives it too).
  void ExpectHealthyPlan(const v1::SolveResult& result) const;
  // A plan that left the server: no NaN or Inf anywhere in it.
  static void ExpectFinite(const v1::SolveResult& result);
  // A refusal: `code`, and a message naming `field`.
  static void ExpectRefused(const absl::Status& status, absl::StatusCode code, const std::string& field);
  static void ExpectRefused(const grpc::Status& status, grpc::StatusCode code, const std::string& field);
  // Opens a Control stream on the client's channel, writes `first` and reads the first
  // answer into `answer` (false: the stream ended without one).
  std::unique_ptr<OpenStream> OpenControl(const v1::ControlRequest& first, v1::ControlResponse* answer, bool* answered);
  // Half-closes `s`, reads what is left and returns the status the stream ends with.
  static grpc::Status EndStream(OpenStream* s);
  // Reports the number of cases of one class of the catalogue: a summary line on stdout
  // ("hostile catalogue: CLASS: N cases") and the test's property "cases.CLASS".
  static void CountCases(const std::string& hostile_class, int cases);

  bench::BenchmarkInstance instance_;
  v1::ProblemSpec spec_;
  std::string healthy_id_;
  v1::SolveResult healthy_result_;
  std::uint64_t rss_before_ = 0;

 private:
  void CreateHealthySession();
};

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_SERVER_HOSTILE_CATALOGUE_H_
