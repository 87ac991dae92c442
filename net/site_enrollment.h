// A unit's first contact with a site whose key it does not have (docs/deploy.md, "Accepting a
// new unit"): it asks the coordinator's enrollment socket to be accepted, with a CURVE key pair
// of its own, until the site's operator accepts or refuses it; accepted, it is handed the
// site's key pair and writes it to its key file (mode 0600), so that from then on it trusts
// that site only and needs no one.
//
// The unit's own key pair is kept beside the key file (KEYFILE.request, mode 0600) until then,
// so a unit restarted while it waits keeps the fingerprint the operator was shown. The site's
// key handed over is checked against the key the beacon showed (the connection's server key)
// and as a pair (net::CheckCurveKeyPair) before it is written.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include "common/base/status.h"
#include "net/curve.h"

namespace sandtable::net {

struct EnrollmentClientOptions {
  std::string endpoint;         // the coordinator's enrollment socket, tcp://HOST:PORT
  std::string site_public_key;  // the coordinator's key, as the beacon showed it
  std::string key_file;         // where the site's key pair is written once accepted
  uint32_t node_id = 0;         // the id the unit will use (shown to the operator)
  std::string host_name;        // shown to the operator (empty: this host's name)
  std::chrono::milliseconds ask_period{250};
  std::chrono::milliseconds timeout{0};  // 0: until decided or stopped
  Status Check() const;
};

// This machine's host name ("unknown" when it cannot be read): what a unit tells the site.
std::string ThisHostName();

// What the unit logs while it waits (called on the caller's thread).
using EnrollmentLog = std::function<void(const std::string& line)>;

// Asks until decided. The site's key pair (also written to key_file) when accepted;
// PERMISSION_DENIED when the operator refused; UNAVAILABLE when stopped or timed out (saying
// how long it asked and what it heard); IO_ERROR when a key file cannot be written.
Expected<CurveKeyPair> EnrollWithSite(const EnrollmentClientOptions& options,
                                      const std::atomic<bool>* stop, const EnrollmentLog& log);

}  // namespace sandtable::net
