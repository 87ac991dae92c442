// ZeroMQ tcp endpoints as a site across hosts needs them (docs/deploy.md): parsed, and the
// address a socket bound to every interface advertises to its peers, which must be one they
// can reach (never 0.0.0.0).
#pragma once

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
