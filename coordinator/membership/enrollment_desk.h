// EnrollmentDesk: the units that ask to join a site whose key they do not have yet, and the
// operator's decisions on them (docs/deploy.md, "Accepting a new unit").
//
// A unit asks on the coordinator's enrollment socket with a CURVE key pair of its own; the desk
// keeps one entry per key (its host name, address, node id, when it first asked). An operator
// lists them and accepts or refuses one by its fingerprint (net::KeyFingerprint) or its whole
// public key; an accepted unit is handed the site's key pair at its next request. Nothing is
// accepted without an operator.
//
// Hostile askers (docs/reliability.md): at most max_pending undecided entries in all and
// max_pending_per_address from one address (a new key from a full address replaces that
// address's oldest, so one host cannot push out the others); an entry not asked again within
// forget_after is dropped; host names are cut to 64 printable characters. Decisions are kept
// (at most max_decided, oldest dropped), in memory: after a coordinator restart a unit that had
// not fetched its keys asks again and waits for a new decision.
#pragma once

#include <chrono>
#include <cstddef>
#include <string>
#include <vector>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "proto/envelope.pb.h"

namespace sandtable::coordinator {

struct EnrollmentDeskOptions {
  size_t max_pending = 64;
  size_t max_pending_per_address = 4;
  size_t max_decided = 1024;
  std::chrono::milliseconds forget_after{60000};
  Status Check() const;
};

enum class EnrollState { kPending, kAccepted, kRefused };
const char* EnrollStateName(EnrollState state);

struct EnrollingUnit {
  std::string public_key;  // Z85
  std::string fingerprint;
  std::string host_name;
  std::string address;
  NodeId node_id = kInvalidNodeId;
  std::chrono::steady_clock::time_point first_asked, last_asked;
  uint64_t requests = 0;
  EnrollState state = EnrollState::kPending;
};

class EnrollmentDesk {
 public:
  using Clock = std::chrono::steady_clock;
  explicit EnrollmentDesk(EnrollmentDeskOptions options = {});

  // A request from the unit with this key; its state after it (a new key is pending). A key
  // that is not 40 characters of Z85 is INVALID_ARGUMENT (the socket's ZAP gives every client
  // one, so this is a defect upstream, refused rather than trusted).
  Expected<EnrollState> OnRequest(const std::string& public_key, const std::string& host_name,
                                  const std::string& address, NodeId node_id,
                                  Clock::time_point now);

  // The operator's decision on one unit that asked (pending, or decided before: a decision can
  // be changed). `who` is a fingerprint or a public key. NOT_FOUND when no unit that asked
  // matches; the unit decided otherwise.
  Expected<EnrollingUnit> Accept(const std::string& who, Clock::time_point now);
  Expected<EnrollingUnit> Refuse(const std::string& who, Clock::time_point now);

  // Pending units (oldest first), then decided ones (latest decision first).
  std::vector<EnrollingUnit> Units(Clock::time_point now);
  size_t pending() const;
  // True when a unit with this key or fingerprint asked and is still kept.
  bool Knows(const std::string& who) { return Find(who) != nullptr; }

  // The request-socket side: answers an operator's EnrollmentRequest.
  wire::EnrollmentReply Serve(const wire::EnrollmentRequest& request, Clock::time_point now);

 private:
  Expected<EnrollingUnit> Decide(const std::string& who, EnrollState state, Clock::time_point now);
  void Forget(Clock::time_point now);
  EnrollingUnit* Find(const std::string& who);

  EnrollmentDeskOptions options_;
  std::vector<EnrollingUnit> pending_;  // in order of first request
  std::vector<EnrollingUnit> decided_;  // in order of decision
};

}  // namespace sandtable::coordinator
