// The ports the tests start server processes on (tests/util/loopback_port.{cc,py}).

#include "tests/util/loopback_port.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>
#include <string>

#include "gtest/gtest.h"

namespace nupmpc::testing {
namespace {

struct Range {
  int first = 32768;
  int last = 60999;
  bool Holds(int port) const { return port >= first && port <= last; }
};

Range Ephemeral() {
  Range range;
  std::ifstream file("/proc/sys/net/ipv4/ip_local_port_range");
  file >> range.first >> range.last;
  return range;
}

// Binds `port` as a server would (SO_REUSEADDR) and keeps it until destroyed.
class Listener {
 public:
  explicit Listener(int port) : fd_(socket(AF_INET, SOCK_STREAM, 0)) {
    const int on = 1;
    setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &on, sizeof(on));
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    address.sin_port = htons(static_cast<std::uint16_t>(port));
    bound_ = bind(fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0 && listen(fd_, 1) == 0;
  }
  ~Listener() { close(fd_); }
  bool bound() const { return bound_; }

 private:
  int fd_;
  bool bound_ = false;
};

TEST(LoopbackPort, IsFreeAndNeverOneTheKernelGivesOutgoingConnections) {
  const Range ephemeral = Ephemeral();
  std::set<int> drawn;
  for (int i = 0; i < 50; ++i) {
    const int port = FreeLoopbackPort();
    ASSERT_GT(port, 0);
    EXPECT_FALSE(ephemeral.Holds(port)) << port << " is in " << ephemeral.first << "-" << ephemeral.last;
    EXPECT_TRUE(Listener(port).bound()) << port;
    drawn.insert(port);
  }
  EXPECT_GT(drawn.size(), 40u) << "drawn at random, not one port over and over";
}

TEST(LoopbackPort, ThePythonHelperDrawsDistinctPortsOutsideTheEphemeralRange) {
  const std::string command = "/usr/bin/python3 " NUPMPC_SOURCE_DIR "/tests/util/loopback_port.py 5";
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  char line[256] = {};
  const bool read = std::fgets(line, sizeof(line), pipe) != nullptr;
  ASSERT_EQ(pclose(pipe), 0) << command;
  ASSERT_TRUE(read);
  std::istringstream ports(line);
  const Range ephemeral = Ephemeral();
  std::set<int> distinct;
  for (int port; ports >> port;) {
    EXPECT_FALSE(ephemeral.Holds(port)) << port;
    EXPECT_TRUE(Listener(port).bound()) << port;
    distinct.insert(port);
  }
  EXPECT_EQ(distinct.size(), 5u) << line;
}

}  // namespace
}  // namespace nupmpc::testing
