// silent_streams: the idle fault scenario's Control streams that never send (tests/soak/faults.py).
// Opens COUNT Control calls, PER_CONNECTION of them on each connection of their own, sends
// nothing on any, and prints how each ended as a JSON list of [code name, details] once all
// have. Written with gRPC's C++ callback API, as the server's own clients are: grpcio's
// asyncio client, which did this before, twice failed to see its calls end at all in CI while
// the server kept serving other clients.
//
//   silent_streams TARGET COUNT [PER_CONNECTION=100] [GIVE_UP_S=30]
//
// Each call carries a deadline of GIVE_UP_S: a call the server never ends shows as the
// client's own "Deadline Exceeded", which the scenario tells apart from the server's
// first_message_timeout_s. Exit 0 with the list; 2 on bad arguments.
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "client/channel_factory.h"
#include "nlohmann/json.hpp"
#include "nupmpc/v1/nupmpc.grpc.pb.h"

namespace {

namespace v1 = nupmpc::v1;

// One Control call that reads (answers would be a finding) and never writes.
class SilentStream : public grpc::ClientBidiReactor<v1::ControlRequest, v1::ControlResponse> {
 public:
  SilentStream(v1::MpcService::Stub& stub, std::chrono::system_clock::time_point give_up) {
    context_.set_deadline(give_up);
    stub.async()->Control(&context_, this);
    StartRead(&answer_);
    StartCall();
  }

  void OnReadDone(bool ok) override {
    if (!ok) return;
    ++answers_;
    StartRead(&answer_);
  }

  void OnDone(const grpc::Status& status) override {
    std::lock_guard<std::mutex> lock(mu_);
    status_ = status;
    done_ = true;
    ended_.notify_all();
  }

  // How the call ended; answers it received before, if any, named in the details.
  nlohmann::json AwaitEnding() {
    std::unique_lock<std::mutex> lock(mu_);
    ended_.wait(lock, [this] { return done_; });
    std::string details = status_.error_message();
    if (answers_ > 0) details += " (after " + std::to_string(answers_) + " answers to a call that sent nothing)";
    return nlohmann::json::array(
        {absl::StatusCodeToString(static_cast<absl::StatusCode>(status_.error_code())), details});
  }

 private:
  grpc::ClientContext context_;
  v1::ControlResponse answer_;
  int answers_ = 0;  // OnReadDone calls are serialised by gRPC; read after OnDone
  std::mutex mu_;
  std::condition_variable ended_;
  bool done_ = false;
  grpc::Status status_;
};

int Usage() {
  std::fprintf(stderr, "usage: silent_streams TARGET COUNT [PER_CONNECTION=100] [GIVE_UP_S=30]\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3 || argc > 5) return Usage();
  const std::string target = argv[1];
  const int count = std::atoi(argv[2]);
  const int per_connection = argc > 3 ? std::atoi(argv[3]) : 100;
  const double give_up_s = argc > 4 ? std::atof(argv[4]) : 30.0;
  if (count < 1 || per_connection < 1 || !(give_up_s > 0)) return Usage();

  const auto give_up =
      std::chrono::system_clock::now() +
      std::chrono::duration_cast<std::chrono::system_clock::duration>(std::chrono::duration<double>(give_up_s));
  std::vector<std::unique_ptr<v1::MpcService::Stub>> stubs;
  for (int first = 0; first < count; first += per_connection) {
    nupmpc::ChannelOptions own;
    own.own_connection = true;  // a connection of its own per channel
    stubs.push_back(v1::MpcService::NewStub(nupmpc::OpenChannel(target, own)));
  }
  std::vector<std::unique_ptr<SilentStream>> streams;
  for (int i = 0; i < count; ++i)
    streams.push_back(std::make_unique<SilentStream>(*stubs[i / per_connection], give_up));
  nlohmann::json endings = nlohmann::json::array();
  for (const auto& stream : streams) endings.push_back(stream->AwaitEnding());
  std::printf("%s\n", endings.dump().c_str());
  return 0;
}
