#include "server/listen_probe.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <memory>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"

namespace nupmpc::server {
namespace {

// Binds `addr` once (an IPv6 address alone, not its IPv4 twin) and closes it: the errno
// of a failed bind, 0 when it bound.
int BindErrno(const sockaddr* addr, socklen_t length) {
  const int fd = socket(addr->sa_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return errno;
  const int yes = 1;
  setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  if (addr->sa_family == AF_INET6) setsockopt(fd, IPPROTO_IPV6, IPV6_V6ONLY, &yes, sizeof(yes));
  const int error = bind(fd, addr, length) == 0 ? 0 : errno;
  close(fd);
  return error;
}

std::string Numeric(const sockaddr* addr, socklen_t length) {
  char host[NI_MAXHOST] = {};
  char port[NI_MAXSERV] = {};
  if (getnameinfo(addr, length, host, sizeof(host), port, sizeof(port), NI_NUMERICHOST | NI_NUMERICSERV) != 0) {
    return "?";
  }
  return addr->sa_family == AF_INET6 ? absl::StrCat("[", host, "]:", port) : absl::StrCat(host, ":", port);
}

bool IsUnspecified(const std::string& host) {
  in_addr v4{};
  in6_addr v6{};
  if (inet_pton(AF_INET, host.c_str(), &v4) == 1) return v4.s_addr == htonl(INADDR_ANY);
  return inet_pton(AF_INET6, host.c_str(), &v6) == 1 && IN6_IS_ADDR_UNSPECIFIED(&v6);
}

}  // namespace

std::optional<ListenHostPort> SplitGrpcTcpAddress(absl::string_view address) {
  for (absl::string_view scheme : {"unix:", "unix-abstract:", "vsock:", "ipv4:", "ipv6:", "dns:"}) {
    if (absl::StartsWith(address, scheme)) return std::nullopt;
  }
  const std::size_t colon = address.rfind(':');
  if (colon == absl::string_view::npos) return std::nullopt;
  absl::string_view host = address.substr(0, colon);
  int port = 0;
  if (!absl::SimpleAtoi(address.substr(colon + 1), &port) || port < 0 || port > 65535) return std::nullopt;
  if (absl::ConsumePrefix(&host, "[")) {
    if (!absl::ConsumeSuffix(&host, "]")) return std::nullopt;
  } else if (absl::StrContains(host, ':')) {
    return std::nullopt;  // an unbracketed IPv6 address or an unknown scheme
  }
  if (host.empty()) return std::nullopt;
  return ListenHostPort{std::string(host), port};
}

absl::Status CheckNotInUse(const ListenHostPort& address, AnyAddress any, const std::string& what) {
  addrinfo hints{};
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  // A null host gives the unspecified address of each family.
  const bool both_families = any == AnyAddress::kBothFamilies && IsUnspecified(address.host);
  addrinfo* found = nullptr;
  const int resolved =
      getaddrinfo(both_families ? nullptr : address.host.c_str(), std::to_string(address.port).c_str(), &hints, &found);
  if (resolved != 0) {
    // gRPC would fail with a message that names neither the host nor the cause (a minimal
    // container has no /etc/hosts, so not even "localhost" resolves there).
    return absl::InvalidArgumentError(absl::StrCat("could not listen on ", what, ": the host '", address.host,
                                                   "' does not resolve (", gai_strerror(resolved),
                                                   "); give a numeric address such as 127.0.0.1 or [::1]"));
  }
  const std::unique_ptr<addrinfo, decltype(&freeaddrinfo)> owned(found, &freeaddrinfo);
  if (address.port == 0) return absl::OkStatus();  // the kernel picks a free port
  for (const addrinfo* a = found; a != nullptr; a = a->ai_next) {
    if (a->ai_family != AF_INET && a->ai_family != AF_INET6) continue;
    if (BindErrno(a->ai_addr, a->ai_addrlen) == EADDRINUSE) {
      return absl::UnavailableError(absl::StrCat("could not listen on ", what, ": ", Numeric(a->ai_addr, a->ai_addrlen),
                                                 " is in use by another process"));
    }
  }
  return absl::OkStatus();
}

}  // namespace nupmpc::server
