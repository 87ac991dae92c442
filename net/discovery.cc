#include "net/discovery.h"

#include <czmq.h>
#include <zmq.h>

#include <algorithm>
#include <cctype>
#include <set>
#include <sstream>
#include <vector>

#include "common/base/log.h"

namespace sandtable::net {
namespace {

constexpr std::string_view kMagic = "SANDTABLE1";
constexpr size_t kMaxBeaconBytes = 255;  // zbeacon's UDP_FRAME_MAX
constexpr size_t kCurveKeyChars = 40;

// CZMQ must not take SIGINT/SIGTERM from the program (it installs handlers on first use).
void CzmqLeavesSignalsAlone() {
  static const bool done = [] {
    zsys_handler_set(nullptr);
    return true;
  }();
  (void)done;
}

bool ValidSiteName(std::string_view name) {
  if (name.empty() || name.size() > 64) return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-';
  });
}

// A CURVE public key as libzmq writes it: 40 characters of Z85 (32 bytes).
bool ValidKey(std::string_view key) {
  if (key.size() != kCurveKeyChars) return false;
  const std::string text(key);
  uint8_t decoded[32];
  return zmq_z85_decode(decoded, text.c_str()) != nullptr;
}

bool ParsePort(std::string_view text, int* port) {
  if (text.empty() || text.size() > 5) return false;
  int v = 0;
  for (char c : text) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + (c - '0');
  }
  if (v < 1 || v > 65535) return false;
  *port = v;
  return true;
}

// Starts a zbeacon actor on `port` (and `interface_name`); its broadcasting address, empty when
// the host has no interface that broadcasts.
Expected<zactor_t*> StartBeacon(int port, const std::string& interface_name, std::string* host) {
  CzmqLeavesSignalsAlone();
  if (!interface_name.empty()) zsys_set_interface(interface_name.c_str());
  zactor_t* actor = zactor_new(zbeacon, nullptr);
  if (actor == nullptr) return UnavailableError("discovery: cannot start the UDP beacon");
  zsock_send(actor, "si", "CONFIGURE", port);
  char* hostname = zstr_recv(actor);
  *host = hostname ? hostname : "";
  zstr_free(&hostname);
  if (host->empty()) {
    zactor_destroy(&actor);
    return UnavailableError(
        "discovery: no interface that broadcasts" +
        (interface_name.empty() ? std::string() : " (asked for " + interface_name + ")") +
        " on UDP port " + std::to_string(port));
  }
  return actor;
}

}  // namespace

std::string SiteBeacon::RequestsEndpoint() const {
  return "tcp://" + host + ":" + std::to_string(requests_port);
}
std::string SiteBeacon::EventsEndpoint() const {
  return "tcp://" + host + ":" + std::to_string(events_port);
}

std::string SiteBeacon::EnrollEndpoint() const {
  return enroll_port > 0 ? "tcp://" + host + ":" + std::to_string(enroll_port) : "";
}

std::string EncodeBeacon(const SiteBeacon& b) {
  std::string out(kMagic);
  out += " site=" + b.site + " key=" + (b.curve_key.empty() ? "-" : b.curve_key) +
         " requests=" + std::to_string(b.requests_port) +
         " events=" + std::to_string(b.events_port);
  if (b.enroll_port > 0) out += " enroll=" + std::to_string(b.enroll_port);
  return out;
}

Expected<SiteBeacon> DecodeBeacon(std::string_view data, const std::string& host) {
  auto bad = [](const std::string& why) {
    return InvalidArgumentError("discovery: not a Sandtable beacon: " + why);
  };
  if (data.size() > kMaxBeaconBytes) return bad("longer than 255 bytes");
  std::istringstream words{std::string(data)};
  std::string magic;
  words >> magic;
  if (magic != kMagic) return bad("no " + std::string(kMagic) + " header");
  SiteBeacon b;
  b.host = host;
  std::set<std::string> seen;
  for (std::string word; words >> word;) {
    const size_t eq = word.find('=');
    if (eq == std::string::npos) return bad("'" + word + "' is not key=value");
    const std::string key = word.substr(0, eq), value = word.substr(eq + 1);
    if (!seen.insert(key).second) return bad("'" + key + "' twice");
    if (key == "site") {
      if (!ValidSiteName(value)) return bad("site name '" + value + "'");
      b.site = value;
    } else if (key == "key") {
      if (value != "-" && !ValidKey(value)) return bad("key is not a Z85 CURVE public key");
      b.curve_key = value == "-" ? "" : value;
    } else if (key == "requests" || key == "events" || key == "enroll") {
      int* port = key == "requests" ? &b.requests_port
                  : key == "events" ? &b.events_port
                                    : &b.enroll_port;
      if (!ParsePort(value, port)) {
        return bad(key + " port '" + value + "'");
      }
    } else {
      return bad("unknown field '" + key + "'");
    }
  }
  for (const char* need : {"site", "key", "requests", "events"}) {
    if (!seen.count(need)) return bad(std::string("no ") + need);
  }
  return b;
}

Expected<std::unique_ptr<BeaconPublisher>> BeaconPublisher::Start(
    int port, const SiteBeacon& beacon, const std::string& interface_name,
    std::chrono::milliseconds interval) {
  if (port < 1 || port > 65535) return InvalidArgumentError("discovery: beacon port 1..65535");
  const std::string data = EncodeBeacon(beacon);
  Expected<SiteBeacon> check = DecodeBeacon(data, "");
  if (!check.ok()) return check.status();
  std::unique_ptr<BeaconPublisher> p(new BeaconPublisher());
  Expected<zactor_t*> actor = StartBeacon(port, interface_name, &p->host_);
  if (!actor.ok()) return actor.status();
  p->actor_ = *actor;
  zsock_send(*actor, "sbi", "PUBLISH", data.data(), data.size(),
             static_cast<int>(std::max<int64_t>(10, interval.count())));
  return p;
}

BeaconPublisher::~BeaconPublisher() {
  auto* actor = static_cast<zactor_t*>(actor_);
  if (actor != nullptr) {
    zstr_sendx(actor, "SILENCE", nullptr);
    zactor_destroy(&actor);
  }
}

Status DiscoveryOptions::Check() const {
  if (port < 1 || port > 65535) return InvalidArgumentError("discovery: port must be 1..65535");
  if (!site.empty() && !ValidSiteName(site)) {
    return InvalidArgumentError("discovery: site name '" + site + "' (1..64 of A-Za-z0-9_.-)");
  }
  if (!trusted_key.empty() && !ValidKey(trusted_key)) {
    return InvalidArgumentError("discovery: the trusted key is not a Z85 CURVE public key");
  }
  if (timeout.count() < 0) return InvalidArgumentError("discovery: timeout must be >= 0");
  return OkStatus();
}

Expected<SiteBeacon> DiscoverSite(
    const DiscoveryOptions& options, const std::atomic<bool>* stop,
    const std::function<void(const SiteBeacon&, const std::string& why)>& heard) {
  ST_RETURN_IF_ERROR(options.Check());
  std::string host;
  Expected<zactor_t*> started = StartBeacon(options.port, options.interface_name, &host);
  if (!started.ok()) return started.status();
  zactor_t* actor = *started;
  zsock_send(actor, "sb", "SUBSCRIBE", kMagic.data(), kMagic.size());
  zsock_set_rcvtimeo(actor, 200);
  using Clock = std::chrono::steady_clock;
  const Clock::time_point start = Clock::now();
  std::chrono::seconds log_gap(5);
  Clock::time_point next_log = start + log_gap;
  std::set<std::string> refused;  // "host why": each said once
  std::string last_refusal;
  const std::string wanted =
      (options.site.empty() ? std::string("any site") : "site " + options.site) +
      (options.enrolling             ? " that accepts new units (enrollment)"
       : options.trusted_key.empty() ? " that is open (no CURVE)"
                                     : " whose key is " + options.trusted_key.substr(0, 8) + "...");
  Expected<SiteBeacon> found = UnavailableError("");
  while (true) {
    if (stop != nullptr && stop->load()) {
      found = UnavailableError("discovery: stopped before a site was found");
      break;
    }
    const Clock::time_point now = Clock::now();
    if (options.timeout.count() > 0 && now - start >= options.timeout) {
      found = UnavailableError(
          "discovery: no " + wanted + " heard on UDP port " + std::to_string(options.port) +
          " in " + std::to_string(options.timeout.count()) + " ms" +
          (last_refusal.empty() ? "" : " (last refused: " + last_refusal + ")"));
      break;
    }
    if (now >= next_log) {
      ST_LOG(kWarning) << "discovery: listening on UDP port " << options.port << " (from " << host
                       << ") for " << wanted << " for "
                       << std::chrono::duration_cast<std::chrono::seconds>(now - start).count()
                       << " s; nothing accepted yet"
                       << (last_refusal.empty() ? "" : " (last refused: " + last_refusal + ")");
      log_gap = std::min<std::chrono::seconds>(2 * log_gap, std::chrono::seconds(60));
      next_log = now + log_gap;
    }
    char* from = zstr_recv(actor);
    if (from == nullptr) continue;  // the receive timeout: look at the clock and the stop flag
    zframe_t* content = zframe_recv(actor);
    const std::string sender = from;
    zstr_free(&from);
    if (content == nullptr) continue;
    const std::string data(reinterpret_cast<const char*>(zframe_data(content)),
                           zframe_size(content));
    zframe_destroy(&content);
    Expected<SiteBeacon> beacon = DecodeBeacon(data, sender);
    std::string why;
    if (!beacon.ok()) {
      why = beacon.status().message();
    } else if (!options.site.empty() && beacon->site != options.site) {
      why = "site " + beacon->site + ", not " + options.site;
    } else if (options.enrolling && (beacon->curve_key.empty() || beacon->enroll_port == 0)) {
      why = beacon->curve_key.empty()
                ? "an open site (no CURVE), which hands out no key to enroll with"
                : "a CURVE site that does not accept new units (its coordinator has no --enroll)";
    } else if (options.enrolling) {
      found = std::move(*beacon);
      break;
    } else if (beacon->curve_key.empty() && !options.accept_open_site) {
      why = "an open site (no CURVE); this unit joins one only with --insecure";
    } else if (!beacon->curve_key.empty() && beacon->curve_key != options.trusted_key) {
      why =
          options.trusted_key.empty()
              ? "a CURVE site; this unit has no key file (--curve-keys) to trust it by"
              : "its key " + beacon->curve_key.substr(0, 8) + "... is not the one this unit trusts";
    } else {
      found = std::move(*beacon);
      break;
    }
    last_refusal = sender + ": " + why;
    if (refused.insert(sender + " " + why).second) {
      ST_LOG(kWarning) << "discovery: heard " << sender << ", refused: " << why;
      if (heard && beacon.ok()) heard(*beacon, why);
    }
  }
  zstr_sendx(actor, "UNSUBSCRIBE", nullptr);
  zactor_destroy(&actor);
  return found;
}

}  // namespace sandtable::net
