#include "net/endpoint.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "common/base/log.h"

namespace sandtable::net {
namespace {

constexpr std::string_view kTcp = "tcp://";

// Closes a file descriptor when it goes.
class Fd {
 public:
  explicit Fd(int fd) : fd_(fd) {}
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  int get() const { return fd_; }

 private:
  int fd_;
};

std::string AddressText(const sockaddr_storage& address) {
  char text[INET6_ADDRSTRLEN] = {};
  if (address.ss_family == AF_INET) {
    const auto* v4 = reinterpret_cast<const sockaddr_in*>(&address);
    ::inet_ntop(AF_INET, &v4->sin_addr, text, sizeof(text));
  } else if (address.ss_family == AF_INET6) {
    const auto* v6 = reinterpret_cast<const sockaddr_in6*>(&address);
    ::inet_ntop(AF_INET6, &v6->sin6_addr, text, sizeof(text));
  }
  return text;
}

}  // namespace

std::string TcpEndpoint::ToString() const {
  const bool v6 = host.find(':') != std::string::npos;
  return std::string(kTcp) + (v6 ? "[" + host + "]" : host) + ":" + port;
}

std::optional<TcpEndpoint> ParseTcpEndpoint(std::string_view endpoint) {
  if (endpoint.substr(0, kTcp.size()) != kTcp) return std::nullopt;
  std::string_view rest = endpoint.substr(kTcp.size());
  TcpEndpoint out;
  size_t colon = 0;
  if (!rest.empty() && rest.front() == '[') {
    const size_t close = rest.find(']');
    if (close == std::string_view::npos || close + 1 >= rest.size() || rest[close + 1] != ':') {
      return std::nullopt;
    }
    out.host = std::string(rest.substr(1, close - 1));
    colon = close + 1;
  } else {
    colon = rest.rfind(':');
    if (colon == std::string_view::npos) return std::nullopt;
    out.host = std::string(rest.substr(0, colon));
    // A bare IPv6 address (several colons, no brackets) is ambiguous: refused.
    if (out.host.find(':') != std::string::npos) return std::nullopt;
  }
  out.port = std::string(rest.substr(colon + 1));
  if (out.host.empty() || out.port.empty()) return std::nullopt;
  if (out.port != "*") {
    for (char c : out.port) {
      if (c < '0' || c > '9') return std::nullopt;
    }
    if (out.port.size() > 5 || std::stoi(out.port) > 65535) return std::nullopt;
  }
  return out;
}

bool IsWildcardHost(std::string_view host) {
  return host.empty() || host == "*" || host == "0.0.0.0" || host == "::";
}

bool IsLoopbackHost(std::string_view host) {
  return host == "localhost" || host == "::1" || host.substr(0, 4) == "127.";
}

bool BeyondLoopback(std::string_view endpoint) {
  const std::optional<TcpEndpoint> e = ParseTcpEndpoint(endpoint);
  return e && !IsLoopbackHost(e->host);
}

void InsecureNotice::Tick(std::chrono::steady_clock::time_point now) {
  if (said_ > 0 && now < next_) return;
  ST_LOG(kWarning) << text_;
  ++said_;
  next_ = now + period_;
}

Expected<std::string> LocalAddressFacing(const std::string& host, const std::string& port) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* found = nullptr;
  if (const int rc = ::getaddrinfo(host.c_str(), port.c_str(), &hints, &found); rc != 0) {
    return UnavailableError("cannot resolve '" + host + "': " + ::gai_strerror(rc));
  }
  std::string last_error = "no address";
  for (addrinfo* a = found; a != nullptr; a = a->ai_next) {
    Fd fd(::socket(a->ai_family, SOCK_DGRAM, 0));
    if (fd.get() < 0 || ::connect(fd.get(), a->ai_addr, a->ai_addrlen) != 0) {
      last_error = std::strerror(errno);
      continue;
    }
    sockaddr_storage local{};
    socklen_t length = sizeof(local);
    if (::getsockname(fd.get(), reinterpret_cast<sockaddr*>(&local), &length) != 0) {
      last_error = std::strerror(errno);
      continue;
    }
    const std::string text = AddressText(local);
    if (!text.empty() && !IsWildcardHost(text)) {
      ::freeaddrinfo(found);
      return text;
    }
  }
  ::freeaddrinfo(found);
  return UnavailableError("no local address routes to '" + host + "' (" + last_error + ")");
}

Expected<Advertised> AdvertisedEndpoint(const std::string& bound, const std::string& toward,
                                        const std::string& advertise_host) {
  const std::optional<TcpEndpoint> own = ParseTcpEndpoint(bound);
  if (!own) return Advertised{bound, ""};
  if (!advertise_host.empty()) {
    if (IsWildcardHost(advertise_host)) {
      return InvalidArgumentError("advertised host '" + advertise_host +
                                  "' is every interface, which no peer can connect to");
    }
    TcpEndpoint chosen{advertise_host, own->port};
    return Advertised{chosen.ToString(), "advertised as given"};
  }
  const std::optional<TcpEndpoint> coordinator = ParseTcpEndpoint(toward);
  if (!IsWildcardHost(own->host)) {
    Advertised out{bound, ""};
    if (IsLoopbackHost(own->host) && coordinator && !IsLoopbackHost(coordinator->host)) {
      out.note = "bound to loopback while the coordinator is at " + coordinator->host +
                 ": peers on other hosts cannot reach " + bound +
                 " (bind tcp://*:PORT or the interface's address)";
    }
    return out;
  }
  if (!coordinator) {
    return InvalidArgumentError("bound to every interface (" + bound +
                                ") and the coordinator's endpoint '" + toward +
                                "' is not tcp: no address to advertise; give one");
  }
  TcpEndpoint chosen = *own;
  if (IsLoopbackHost(coordinator->host)) {
    chosen.host = "127.0.0.1";
    return Advertised{chosen.ToString(), "the coordinator is on this host: advertised on loopback"};
  }
  Expected<std::string> facing = LocalAddressFacing(coordinator->host, coordinator->port);
  if (!facing.ok()) {
    return UnavailableError("bound to every interface (" + bound + "): no address to advertise: " +
                            facing.status().message() + "; give one");
  }
  chosen.host = *facing;
  return Advertised{chosen.ToString(),
                    "the interface facing the coordinator at " + coordinator->host};
}

}  // namespace sandtable::net
