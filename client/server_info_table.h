#ifndef NUPMPC_CLIENT_SERVER_INFO_TABLE_H_
#define NUPMPC_CLIENT_SERVER_INFO_TABLE_H_

// `nupmpc info --format table`: GetServerInfoResponse as an aligned key/value listing for
// people (--format json prints the proto JSON for programs).

#include <string>

#include "nupmpc/v1/nupmpc.pb.h"

namespace nupmpc {

std::string ServerInfoTable(const v1::GetServerInfoResponse& info);

}  // namespace nupmpc

#endif  // NUPMPC_CLIENT_SERVER_INFO_TABLE_H_
