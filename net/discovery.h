// Finding the site on the LAN (docs/deploy.md, "Discovery"): the coordinator broadcasts a UDP
// beacon (CZMQ's zbeacon, a maintained library that ZeroMQ's own tools use; chosen over DNS-SD
// through Avahi because it needs no daemon on the hosts and works in the lab's network
// namespaces), and a unit with no coordinator address listens for it. The beacon names the
// site, its two ports and the coordinator's CURVE public key; a unit joins only a site whose
// key it trusts (the key in its site key file), or an open site (no CURVE) when it runs open
// itself (--insecure), or, when it has no site key yet, a site that offers enrollment (the
// operator then accepts it: net/site_enrollment.h).
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "common/base/status.h"

namespace sandtable::net {

inline constexpr int kDefaultBeaconPort = 5670;
inline constexpr std::chrono::milliseconds kBeaconInterval{1000};

struct SiteBeacon {
  std::string site;       // the site's name: 1..64 of [A-Za-z0-9_.-]
  std::string curve_key;  // the coordinator's CURVE public key (Z85, 40 chars); empty: open site
  int requests_port = 0;  // the coordinator's ROUTER
  int events_port = 0;    // the coordinator's events socket
  int enroll_port = 0;    // its enrollment socket (0: none; "enroll=" is optional in the beacon)
  std::string host;       // where the beacon came from (set by the listener)

  std::string RequestsEndpoint() const;  // tcp://HOST:REQUESTS
  std::string EventsEndpoint() const;
  std::string EnrollEndpoint() const;  // empty without an enrollment port
};

// The beacon's bytes (at most 255, zbeacon's limit) and back; INVALID_ARGUMENT for anything
// that is not a version 1 Sandtable beacon with valid fields.
std::string EncodeBeacon(const SiteBeacon& beacon);
Expected<SiteBeacon> DecodeBeacon(std::string_view data, const std::string& host);

// Broadcasts `beacon` every `interval` on UDP `port` until destroyed.
class BeaconPublisher {
 public:
  // `interface_name` picks the interface (empty: CZMQ's choice, the first that broadcasts).
  static Expected<std::unique_ptr<BeaconPublisher>> Start(
      int port, const SiteBeacon& beacon, const std::string& interface_name = "",
      std::chrono::milliseconds interval = kBeaconInterval);
  ~BeaconPublisher();
  BeaconPublisher(const BeaconPublisher&) = delete;
  BeaconPublisher& operator=(const BeaconPublisher&) = delete;
  const std::string& host() const { return host_; }  // the address it broadcasts from

 private:
  BeaconPublisher() = default;
  void* actor_ = nullptr;  // zactor_t
  std::string host_;
};

struct DiscoveryOptions {
  int port = kDefaultBeaconPort;
  std::string site;               // only this site (empty: any)
  std::string trusted_key;        // the CURVE public key a site must show (empty: open sites only)
  bool accept_open_site = false;  // an open site is joined only when the unit runs open too
  // A unit that has no site key yet (net/site_enrollment.h): any CURVE site with an enrollment
  // port is taken (the operator's acceptance is what makes it trusted).
  bool enrolling = false;
  std::string interface_name;            // empty: CZMQ's choice
  std::chrono::milliseconds timeout{0};  // 0: until found or stopped
  Status Check() const;
};

// Listens for beacons until one passes the options (returned), `stop` is set (UNAVAILABLE), or
// the timeout passes (UNAVAILABLE, saying what was heard). Every site heard and refused is
// passed to `heard` once with the reason (for the log). While nothing is found it logs what it
// listens for after 5 s, then at doubling intervals up to a minute.
Expected<SiteBeacon> DiscoverSite(
    const DiscoveryOptions& options, const std::atomic<bool>* stop = nullptr,
    const std::function<void(const SiteBeacon&, const std::string& why)>& heard = nullptr);

}  // namespace sandtable::net
