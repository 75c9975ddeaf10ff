#include "tests/util/loopback_port.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <fstream>
#include <random>

namespace nupmpc::testing {
namespace {

// Ports under this are left to services (and to what people start by hand).
constexpr int kLowestPort = 10000;
// Where the range below the ephemeral ports is narrower than this, the range above is used.
constexpr int kLeastPorts = 1000;

struct PortRange {
  int first;
  int last;
};

PortRange EphemeralRange() {
  PortRange range{32768, 60999};  // Linux's default
  std::ifstream file("/proc/sys/net/ipv4/ip_local_port_range");
  PortRange read{};
  if (file >> read.first >> read.last && read.first <= read.last) range = read;
  return range;
}

// Without SO_REUSEADDR, as a probe: a port with connections in TIME_WAIT is passed over.
bool Bindable(int port) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return false;
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  address.sin_port = htons(static_cast<std::uint16_t>(port));
  const bool bound = bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
  close(fd);
  return bound;
}

}  // namespace

int FreeLoopbackPort() {
  const PortRange ephemeral = EphemeralRange();
  const PortRange usable = ephemeral.first - kLowestPort >= kLeastPorts ? PortRange{kLowestPort, ephemeral.first - 1}
                                                                        : PortRange{ephemeral.last + 1, 65535};
  if (usable.first > usable.last) return 0;
  std::mt19937 random(std::random_device{}());
  std::uniform_int_distribution<int> draw(usable.first, usable.last);
  for (int attempt = 0; attempt < 1000; ++attempt) {
    if (const int port = draw(random); Bindable(port)) return port;
  }
  return 0;
}

}  // namespace nupmpc::testing
