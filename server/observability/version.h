#ifndef NUPMPC_SERVER_OBSERVABILITY_VERSION_H_
#define NUPMPC_SERVER_OBSERVABILITY_VERSION_H_

namespace nupmpc::server {
inline constexpr const char* kVersion = NUPMPC_VERSION;  // from CMake's project(VERSION)
}  // namespace nupmpc::server

#endif  // NUPMPC_SERVER_OBSERVABILITY_VERSION_H_
