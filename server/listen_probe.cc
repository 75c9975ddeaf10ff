#include "server/listen_probe.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <memory>
#include <optional>
#include <string>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"

namespace nupmpc::server {
namespace {

struct HostPort {
  std::string host;  ///< without brackets; empty: every address
  std::string port;
};

// gRPC's TCP forms; nullopt for what is not TCP (unix:, unix-abstract:, vsock:) or does
// not parse (the listener reports that).
std::optional<HostPort> SplitTcpAddress(absl::string_view address) {
  if (!absl::ConsumePrefix(&address, "ipv4:")) absl::ConsumePrefix(&address, "ipv6:");
  const std::size_t colon = address.rfind(':');
  if (colon == absl::string_view::npos) return std::nullopt;
  absl::string_view host = address.substr(0, colon);
  const absl::string_view port = address.substr(colon + 1);
  int number = 0;
  if (!absl::SimpleAtoi(port, &number) || number < 0 || number > 65535) return std::nullopt;
  if (absl::ConsumePrefix(&host, "[")) {
    if (!absl::ConsumeSuffix(&host, "]")) return std::nullopt;
  } else if (absl::StrContains(host, ':')) {
    return std::nullopt;  // a scheme (unix:/path:1 and the like), or an unbracketed IPv6 address
  }
  return HostPort{std::string(host), std::string(port)};
}

// Binds `addr` once (SO_REUSEADDR, as the listeners do: connections of an earlier run in
// TIME_WAIT do not count; an IPv6 address alone, not its IPv4 twin) and closes it.
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

}  // namespace

absl::Status CheckNotInUse(const std::string& address, const std::string& what) {
  const std::optional<HostPort> split = SplitTcpAddress(address);
  if (!split.has_value() || split->port == "0") return absl::OkStatus();
  addrinfo hints{};
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  // An empty host or "::" is every address of both families (gRPC binds both); getaddrinfo
  // gives one wildcard per family for a null host.
  const bool every_address = split->host.empty() || split->host == "::";
  addrinfo* found = nullptr;
  if (getaddrinfo(every_address ? nullptr : split->host.c_str(), split->port.c_str(), &hints, &found) != 0) {
    return absl::OkStatus();  // unresolvable: the listener says so
  }
  const std::unique_ptr<addrinfo, decltype(&freeaddrinfo)> owned(found, &freeaddrinfo);
  for (const addrinfo* a = found; a != nullptr; a = a->ai_next) {
    if (a->ai_family != AF_INET && a->ai_family != AF_INET6) continue;
    if (BindErrno(a->ai_addr, a->ai_addrlen) == EADDRINUSE) {
      return absl::UnavailableError(
          absl::StrCat("could not listen on ", what, ": ", Numeric(a->ai_addr, a->ai_addrlen), " is in use by another process"));
    }
  }
  return absl::OkStatus();
}

}  // namespace nupmpc::server
