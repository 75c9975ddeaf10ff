#ifndef NUPMPC_SERVER_OBSERVABILITY_PROCESS_MEMORY_H_
#define NUPMPC_SERVER_OBSERVABILITY_PROCESS_MEMORY_H_

#include <cstdint>

namespace nupmpc::server {

// Resident set size of this process in bytes (Linux /proc/self/statm; 0 elsewhere).
std::uint64_t ResidentMemoryBytes();

// Hands freed heap pages back to the OS. glibc keeps memory freed by closed sessions in
// its arenas (the worker threads' arenas especially), so without this the RSS of a server
// that once held many sessions never comes down. Costs a heap walk: call it off the hot
// path (the janitor does, after sessions were closed).
void ReleaseFreedMemory();

}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_OBSERVABILITY_PROCESS_MEMORY_H_
