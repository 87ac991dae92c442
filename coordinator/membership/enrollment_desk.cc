#include "coordinator/membership/enrollment_desk.h"

#include <algorithm>
#include <cctype>

#include "net/curve.h"

namespace sandtable::coordinator {
namespace {

constexpr size_t kMaxHostNameChars = 64;

// What an operator is shown of a name the unit chose: printable ASCII, at most 64 characters.
std::string Printable(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (out.size() == kMaxHostNameChars) break;
    out += std::isprint(static_cast<unsigned char>(c)) ? c : '?';
  }
  return out;
}

bool Matches(const EnrollingUnit& unit, const std::string& who) {
  return !who.empty() && (unit.public_key == who || unit.fingerprint == who);
}

}  // namespace

Status EnrollmentDeskOptions::Check() const {
  if (max_pending < 1 || max_pending > 4096) {
    return InvalidArgumentError("enrollment: max_pending must be in [1, 4096]");
  }
  if (max_pending_per_address < 1 || max_pending_per_address > max_pending) {
    return InvalidArgumentError("enrollment: max_pending_per_address must be in [1, max_pending]");
  }
  if (max_decided < 1 || max_decided > 65536) {
    return InvalidArgumentError("enrollment: max_decided must be in [1, 65536]");
  }
  if (forget_after.count() < 1000) {
    return InvalidArgumentError("enrollment: forget_after must be at least 1000 ms");
  }
  return OkStatus();
}

const char* EnrollStateName(EnrollState state) {
  switch (state) {
    case EnrollState::kPending:
      return "pending";
    case EnrollState::kAccepted:
      return "accepted";
    case EnrollState::kRefused:
      return "refused";
  }
  return "?";
}

EnrollmentDesk::EnrollmentDesk(EnrollmentDeskOptions options) : options_(options) {}

void EnrollmentDesk::Forget(Clock::time_point now) {
  std::erase_if(pending_, [&](const EnrollingUnit& unit) {
    return now - unit.last_asked > options_.forget_after;
  });
}

EnrollingUnit* EnrollmentDesk::Find(const std::string& who) {
  for (auto* list : {&pending_, &decided_}) {
    for (EnrollingUnit& unit : *list) {
      if (Matches(unit, who)) return &unit;
    }
  }
  return nullptr;
}

size_t EnrollmentDesk::pending() const { return pending_.size(); }

Expected<EnrollState> EnrollmentDesk::OnRequest(const std::string& public_key,
                                                const std::string& host_name,
                                                const std::string& address, NodeId node_id,
                                                Clock::time_point now) {
  const std::string fingerprint = net::KeyFingerprint(public_key);
  if (fingerprint.empty()) {
    return InvalidArgumentError("enrollment: a request without a CURVE public key");
  }
  Forget(now);
  if (EnrollingUnit* known = Find(public_key)) {
    known->last_asked = now;
    ++known->requests;
    known->host_name = Printable(host_name);
    known->address = address;
    known->node_id = node_id;
    return known->state;
  }
  // Room: a full address gives up its oldest entry, a full desk its least recently asked.
  const auto from_address =
      std::count_if(pending_.begin(), pending_.end(),
                    [&](const EnrollingUnit& u) { return u.address == address; });
  if (static_cast<size_t>(from_address) >= options_.max_pending_per_address) {
    pending_.erase(std::find_if(pending_.begin(), pending_.end(),
                                [&](const EnrollingUnit& u) { return u.address == address; }));
  } else if (pending_.size() >= options_.max_pending) {
    pending_.erase(std::min_element(pending_.begin(), pending_.end(),
                                    [](const EnrollingUnit& a, const EnrollingUnit& b) {
                                      return a.last_asked < b.last_asked;
                                    }));
  }
  EnrollingUnit unit;
  unit.public_key = public_key;
  unit.fingerprint = fingerprint;
  unit.host_name = Printable(host_name);
  unit.address = address;
  unit.node_id = node_id;
  unit.first_asked = unit.last_asked = now;
  unit.requests = 1;
  pending_.push_back(std::move(unit));
  return EnrollState::kPending;
}

Expected<EnrollingUnit> EnrollmentDesk::Decide(const std::string& who, EnrollState state,
                                               Clock::time_point now) {
  Forget(now);
  EnrollingUnit* unit = Find(who);
  if (unit == nullptr) {
    return NotFoundError("enrollment: no unit that asked has the key or fingerprint '" +
                         Printable(who) + "'");
  }
  EnrollingUnit decided = *unit;
  decided.state = state;
  const std::string key = decided.public_key;
  std::erase_if(pending_, [&](const EnrollingUnit& u) { return u.public_key == key; });
  std::erase_if(decided_, [&](const EnrollingUnit& u) { return u.public_key == key; });
  decided_.push_back(decided);
  if (decided_.size() > options_.max_decided) decided_.erase(decided_.begin());
  return decided;
}

Expected<EnrollingUnit> EnrollmentDesk::Accept(const std::string& who, Clock::time_point now) {
  return Decide(who, EnrollState::kAccepted, now);
}

Expected<EnrollingUnit> EnrollmentDesk::Refuse(const std::string& who, Clock::time_point now) {
  return Decide(who, EnrollState::kRefused, now);
}

std::vector<EnrollingUnit> EnrollmentDesk::Units(Clock::time_point now) {
  Forget(now);
  std::vector<EnrollingUnit> out = pending_;
  out.insert(out.end(), decided_.rbegin(), decided_.rend());
  return out;
}

wire::EnrollmentReply EnrollmentDesk::Serve(const wire::EnrollmentRequest& request,
                                            Clock::time_point now) {
  wire::EnrollmentReply reply;
  reply.set_ok(true);
  if (!request.accept().empty() && !request.refuse().empty()) {
    reply.set_ok(false);
    reply.set_message("enrollment: accept or refuse one unit per request, not both");
  } else if (!request.accept().empty() || !request.refuse().empty()) {
    const bool accept = !request.accept().empty();
    Expected<EnrollingUnit> decided =
        accept ? Accept(request.accept(), now) : Refuse(request.refuse(), now);
    if (decided.ok()) {
      reply.set_message(std::string(accept ? "accepted" : "refused") + " unit " +
                        decided->fingerprint + " (" + decided->host_name + " at " +
                        decided->address + ", node " + std::to_string(decided->node_id) + ")");
    } else {
      reply.set_ok(false);
      reply.set_message(decided.status().message());
    }
  }
  for (const EnrollingUnit& unit : Units(now)) {
    wire::EnrollingUnit* out = reply.add_units();
    out->set_fingerprint(unit.fingerprint);
    out->set_public_key(unit.public_key);
    out->set_host_name(unit.host_name);
    out->set_address(unit.address);
    out->set_node_id(unit.node_id);
    out->set_waiting_s(std::chrono::duration<double>(now - unit.first_asked).count());
    out->set_requests(unit.requests);
    out->set_state(EnrollStateName(unit.state));
  }
  return reply;
}

}  // namespace sandtable::coordinator
