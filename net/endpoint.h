// ZeroMQ tcp endpoints as a site across hosts needs them (docs/deploy.md): parsed, and the
// address a socket bound to every interface advertises to its peers, which must be one they
// can reach (never 0.0.0.0).
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <string_view>

#include "common/base/status.h"

namespace sandtable::net {

struct TcpEndpoint {
  std::string host;  // a name, an IPv4 address, an IPv6 address (no brackets), or "*"
  std::string port;  // a number, or "*" (any free port; a bound socket reports the number)
  std::string ToString() const;  // tcp://HOST:PORT, IPv6 hosts in brackets
};

// "tcp://HOST:PORT" ("tcp://[V6]:PORT"); nullopt for anything else (ipc://, inproc://, no port).
std::optional<TcpEndpoint> ParseTcpEndpoint(std::string_view endpoint);

// "*", "0.0.0.0", "::" or "": every interface.
bool IsWildcardHost(std::string_view host);
// "localhost", 127.0.0.0/8 or ::1.
bool IsLoopbackHost(std::string_view host);

// A tcp endpoint other hosts may reach: its host is not loopback (every interface included).
bool BeyondLoopback(std::string_view endpoint);

// What an open site (--insecure: beyond loopback without CURVE) logs at start and every
// `period` after, so that a log read at any time shows it.
class InsecureNotice {
 public:
  explicit InsecureNotice(std::string text, std::chrono::seconds period = std::chrono::seconds(60))
      : text_(std::move(text)), period_(period) {}
  // Logs the notice when it is due (the first call logs it).
  void Tick(std::chrono::steady_clock::time_point now);
  int times_said() const { return said_; }

 private:
  std::string text_;
  std::chrono::seconds period_;
  std::chrono::steady_clock::time_point next_{};
  int said_ = 0;
};

// The local address this host's routing table uses to reach `host`:`port` (a name is resolved
// first): a UDP socket connected to it, no packet sent, asked for its own address. The
// interface facing a coordinator on a host with several of them.
Expected<std::string> LocalAddressFacing(const std::string& host, const std::string& port);

struct Advertised {
  std::string endpoint;  // what peers are told to connect to
  std::string note;      // how it was chosen, or why peers elsewhere may not reach it (logged)
};

// The endpoint to advertise for a socket that reports `bound` (ZeroMQ's last endpoint):
//   - not tcp (ipc, inproc): `bound` itself;
//   - `advertise_host` given (an operator's choice): that host with the bound port;
//   - bound to one address: `bound` itself (noted when it is loopback and `toward` is not);
//   - bound to every interface: the local address facing `toward` (the coordinator's endpoint;
//     127.0.0.1 when that is loopback). An error when none is found: advertising 0.0.0.0
//     would send every peer to itself.
Expected<Advertised> AdvertisedEndpoint(const std::string& bound, const std::string& toward,
                                        const std::string& advertise_host = "");

}  // namespace sandtable::net
