#ifndef NUPMPC_LOADTEST_LOADTEST_REPORT_H_
#define NUPMPC_LOADTEST_LOADTEST_REPORT_H_

// nupmpc-loadtest's output: a table for people, one JSON document for scripts. Every
// level is set against the core-alone baseline, gRPC's own round trip and (when run) the
// same level against a zero-work echo server, all measured in the same run.

#include <string>
#include <vector>

#include "loadtest/core_baseline.h"
#include "loadtest/idle_sessions.h"
#include "loadtest/load_level.h"
#include "loadtest/transport_floor.h"
#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc::loadtest {

struct RunHeader {
  std::string instance;
  std::string target;
  v1::GetServerInfoResponse server;
  CoreBaseline baseline;
  TransportFloor transport;
  double capacity_per_s = 0.0;  ///< worker threads / core median solve time
  bool echo = false;            ///< every level is also run against the zero-work echo server
};

void PrintHeader(const RunHeader& header);
void PrintLevel(const RunHeader& header, const LevelReport& level);
// The row of a level run against the echo server, below the real level's row.
void PrintEchoLevel(const LevelReport& echo);
void PrintJson(const RunHeader& header, const std::vector<LevelReport>& levels);
void PrintIdleSessions(const std::string& instance, const IdleSessionsReport& report, bool json);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_LOADTEST_REPORT_H_
