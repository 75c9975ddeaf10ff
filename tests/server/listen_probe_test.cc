// CheckNotInUse: a server refuses to start when another process holds a port on any of the
// addresses it would listen on (gRPC and the metrics listener would start on the others
// and leave that process answering part of the clients), and only then.
#include "server/listen_probe.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <optional>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace nupmpc::server {
namespace {

using ::testing::HasSubstr;

// A socket of this test bound to a loopback port of `family` (0: any free port) and
// listening, as another server's would be.
class HeldPort {
 public:
  explicit HeldPort(int family, int port = 0) {
    fd_ = socket(family, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0) {
      error_ = errno;
      return;
    }
    const int yes = 1;
    setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
    sockaddr_storage addr{};
    socklen_t length = 0;
    if (family == AF_INET6) {
      setsockopt(fd_, IPPROTO_IPV6, IPV6_V6ONLY, &yes, sizeof(yes));
      auto* v6 = reinterpret_cast<sockaddr_in6*>(&addr);
      v6->sin6_family = AF_INET6;
      v6->sin6_addr = in6addr_loopback;
      v6->sin6_port = htons(static_cast<std::uint16_t>(port));
      length = sizeof(*v6);
    } else {
      auto* v4 = reinterpret_cast<sockaddr_in*>(&addr);
      v4->sin_family = AF_INET;
      v4->sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      v4->sin_port = htons(static_cast<std::uint16_t>(port));
      length = sizeof(*v4);
    }
    if (bind(fd_, reinterpret_cast<sockaddr*>(&addr), length) != 0 || listen(fd_, 4) != 0) {
      error_ = errno;
      return;
    }
    getsockname(fd_, reinterpret_cast<sockaddr*>(&addr), &length);
    port_ = ntohs(family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&addr)->sin6_port
                                     : reinterpret_cast<sockaddr_in*>(&addr)->sin_port);
  }
  ~HeldPort() { Release(); }
  void Release() {
    if (fd_ >= 0) close(fd_);
    fd_ = -1;
  }
  int fd() const { return fd_; }
  int port() const { return port_; }
  int error() const { return error_; }  ///< errno of a socket, bind or listen that failed; 0 when held

 private:
  int fd_ = -1;
  int port_ = 0;
  int error_ = 0;
};

ListenHostPort At(absl::string_view host, int port) { return {std::string(host), port}; }

TEST(SplitGrpcTcpAddress, TakesHostPortAndBracketedIpv6AndLeavesOtherFormsToGrpc) {
  const std::optional<ListenHostPort> v4 = SplitGrpcTcpAddress("127.0.0.1:50051");
  ASSERT_TRUE(v4.has_value());
  EXPECT_EQ(v4->host, "127.0.0.1");
  EXPECT_EQ(v4->port, 50051);
  const std::optional<ListenHostPort> v6 = SplitGrpcTcpAddress("[::]:7");
  ASSERT_TRUE(v6.has_value());
  EXPECT_EQ(v6->host, "::");
  EXPECT_EQ(v6->port, 7);
  EXPECT_EQ(SplitGrpcTcpAddress("localhost:0")->port, 0);
  for (const char* other :
       {"unix:/run/nupmpc.sock", "unix:8080", "unix-abstract:1234", "vsock:3:5000", "ipv4:127.0.0.1:5",
        "dns:///localhost:5", "::1:5", ":5", "localhost", "host:70000", "[::1:5", "host:x"}) {
    EXPECT_FALSE(SplitGrpcTcpAddress(other).has_value()) << other;
  }
}

TEST(CheckNotInUse, AnAddressWhosePortAnotherSocketHoldsIsRefusedNamingIt) {
  HeldPort held(AF_INET);
  ASSERT_EQ(held.error(), 0);
  for (const AnyAddress any : {AnyAddress::kBothFamilies, AnyAddress::kAsGiven}) {
    for (const absl::string_view host : {"127.0.0.1", "0.0.0.0"}) {
      const absl::Status s = CheckNotInUse(At(host, held.port()), any, absl::StrCat("--address ", host));
      EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable) << host;
      EXPECT_THAT(s.message(), HasSubstr(absl::StrCat("could not listen on --address ", host, ": "))) << host;
      EXPECT_THAT(s.message(), HasSubstr(absl::StrCat(":", held.port(), " is in use by another process"))) << host;
    }
  }
  held.Release();
  EXPECT_TRUE(CheckNotInUse(At("127.0.0.1", held.port()), AnyAddress::kBothFamilies, "x").ok())
      << "free again once released";
}

// A minimal container has no /etc/hosts: there not even "localhost" resolves, and the probe
// must not take an address it cannot resolve for a free one. ".invalid" never resolves
// (RFC 2606).
TEST(CheckNotInUse, AHostThatDoesNotResolveIsRefusedNamingIt) {
  for (const int port : {0, 50051}) {
    for (const AnyAddress any : {AnyAddress::kBothFamilies, AnyAddress::kAsGiven}) {
      const absl::Status s = CheckNotInUse(At("no-such-host.invalid", port), any, "--address no-such-host.invalid");
      EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << port;
      EXPECT_THAT(s.message(), HasSubstr("could not listen on --address no-such-host.invalid: the host "
                                         "'no-such-host.invalid' does not resolve"));
    }
  }
}

TEST(CheckNotInUse, FreePortsAndPortZeroPass) {
  HeldPort held(AF_INET);
  ASSERT_EQ(held.error(), 0);
  const int free_port = held.port();
  held.Release();
  EXPECT_TRUE(CheckNotInUse(At("127.0.0.1", free_port), AnyAddress::kBothFamilies, "x").ok());
  EXPECT_TRUE(CheckNotInUse(At("0.0.0.0", free_port), AnyAddress::kBothFamilies, "x").ok());
  EXPECT_TRUE(CheckNotInUse(At("127.0.0.1", 0), AnyAddress::kBothFamilies, "x").ok());
  EXPECT_TRUE(CheckNotInUse(At("::", 0), AnyAddress::kBothFamilies, "x").ok());
  // The probe leaves nothing bound: the port can be held right after.
  HeldPort again(AF_INET, free_port);
  EXPECT_EQ(again.error(), 0);
}

// A restart while the last run's connections wait in TIME_WAIT must still start: only a
// socket that holds the port counts.
TEST(CheckNotInUse, ConnectionsOfAClosedListenerInTimeWaitDoNotCount) {
  HeldPort listener(AF_INET);
  ASSERT_EQ(listener.error(), 0);
  const int client = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(client, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  to.sin_port = htons(static_cast<std::uint16_t>(listener.port()));
  ASSERT_EQ(connect(client, reinterpret_cast<sockaddr*>(&to), sizeof(to)), 0);
  const int accepted = accept(listener.fd(), nullptr, nullptr);
  ASSERT_GE(accepted, 0);
  close(accepted);  // the server side closes first: its end goes to TIME_WAIT
  char byte = 0;
  ASSERT_EQ(read(client, &byte, 1), 0);  // the close arrived
  close(client);
  listener.Release();
  EXPECT_TRUE(CheckNotInUse(At("127.0.0.1", listener.port()), AnyAddress::kBothFamilies, "x").ok());
}

// The case the probe exists for: IPv6's loopback held by another server, IPv4's free.
// gRPC given [::]:PORT or 0.0.0.0:PORT (either is every address of both families to it)
// would start on IPv4 alone; the probe refuses both. cpp-httplib binds 0.0.0.0 on IPv4
// only, so there it passes. Where this machine has no IPv6 loopback, no port can be held
// on it, and the probe lets [::1] through for the listener to report.
TEST(CheckNotInUse, EveryAddressRefusedWhenOneFamilysPortIsHeld) {
  HeldPort v6(AF_INET6);
  if (v6.error() != 0) {
    EXPECT_THAT(v6.error(), ::testing::AnyOf(EADDRNOTAVAIL, EAFNOSUPPORT)) << "no IPv6 loopback here";
    EXPECT_TRUE(CheckNotInUse(At("::1", 5000), AnyAddress::kBothFamilies, "x").ok());
    return;
  }
  for (const absl::string_view host : {"::", "0.0.0.0", "::1"}) {
    const absl::Status s = CheckNotInUse(At(host, v6.port()), AnyAddress::kBothFamilies, "--address");
    EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable) << host;
    EXPECT_THAT(s.message(), HasSubstr(absl::StrCat("]:", v6.port(), " is in use by another process"))) << host;
  }
  EXPECT_TRUE(CheckNotInUse(At("0.0.0.0", v6.port()), AnyAddress::kAsGiven, "x").ok());
  EXPECT_TRUE(CheckNotInUse(At("127.0.0.1", v6.port()), AnyAddress::kBothFamilies, "x").ok());
}

}  // namespace
}  // namespace nupmpc::server
