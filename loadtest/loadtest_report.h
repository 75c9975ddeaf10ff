#ifndef NUPMPC_LOADTEST_LOADTEST_REPORT_H_
#define NUPMPC_LOADTEST_LOADTEST_REPORT_H_

// nupmpc-loadtest's output: a table for people, one JSON document for scripts. Every
// level is set against the core-alone baseline, gRPC's own round trip and (when run) the
// same level against a zero-work echo server, all measured in the same run.

#include <string>
#include <vector>

#include "loadtest/core_baseline.h"
#include "loadtest/fleet_level.h"
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
  int solve_cores = 1;          ///< solves the server runs at once on its CPUs (UsableCores)
  int fleet_cores = 1;          ///< its workers on its CPUs (a SolveFleet call runs on the workers)
  double capacity_per_s = 0.0;  ///< solve_cores / core median solve time
  bool echo = false;            ///< every level is also run against the zero-work echo server
  bool inline_solve = false;    ///< and against the echo busy for the core median in its reaction
  bool bare = false;            ///< and against the bare server solving in its reaction
  std::string peer_cpus;        ///< CPUs the echo peers and the core baseline ran on ("": not pinned)
  std::string generator_cpus;   ///< CPUs the load generator ran on
  int rounds = 1;               ///< runs of each level against each server, interleaved
};

// How many solves a server runs at once on the CPUs it has: `cores` (its solver cores or
// its workers), at most the CPUs of its affinity list `cpus` (GetServerInfoResponse.cpus;
// `cores` when the list is empty or unreadable).
int UsableCores(int cores, const std::string& cpus);

void PrintHeader(const RunHeader& header);
void PrintLevel(const RunHeader& header, const LevelReport& level);
// The row of a level run against a peer (`label`: echo, inline or bare), below the real
// level's row; its overhead is the p50 above `busy_ms`, the echo's stand-in solve.
void PrintPeerLevel(const char* label, const LevelReport& peer, double busy_ms);
// The server's level set against the inline and the bare peers': solves/s ratio, p50
// difference, p99 ratio, and how evenly the streams were served.
void PrintRatios(const LevelReport& level);
void PrintJson(const RunHeader& header, const std::vector<LevelReport>& levels);
// --fleet: S sessions per SolveFleet call against S separate Control streams, same run.
void PrintFleet(const RunHeader& header, const FleetReport& fleet, const LevelReport& separate,
                const FleetCoreBaseline& core_in_turn, bool json);
void PrintIdleSessions(const std::string& instance, const IdleSessionsReport& report, bool json);

}  // namespace nupmpc::loadtest

#endif  // NUPMPC_LOADTEST_LOADTEST_REPORT_H_
