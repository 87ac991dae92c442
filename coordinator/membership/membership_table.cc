#include "coordinator/membership/membership_table.h"

#include <string>

namespace sandtable::coordinator {

Status MembershipOptions::Check() const {
  if (heartbeat_period.count() <= 0) {
    return InvalidArgumentError("membership: heartbeat_period must be > 0 ms");
  }
  if (misses_allowed < 1) {
    return InvalidArgumentError("membership: misses_allowed = " + std::to_string(misses_allowed) +
                                " must be >= 1");
  }
  return OkStatus();
}

HelloOutcome MembershipTable::OnHello(NodeId id, const wire::Hello& hello, Clock::time_point now) {
  auto it = members_.find(id);
  if (it != members_.end() && it->second.member.incarnation() == hello.incarnation()) {
    // The same process saying hello again (its HelloAck was lost): nothing changes.
    it->second.last_heard = now;
    return HelloOutcome::kRepeated;
  }
  const HelloOutcome outcome =
      it == members_.end() ? HelloOutcome::kJoined : HelloOutcome::kRestarted;
  Entry& entry = members_[id];
  entry.member.set_node_id(id);
  entry.member.set_incarnation(hello.incarnation());
  *entry.member.mutable_endpoints() = hello.endpoints();
  *entry.member.mutable_capabilities() = hello.capabilities();
  entry.member.set_joined_time_ns(
      std::chrono::duration_cast<std::chrono::nanoseconds>(now.time_since_epoch()).count());
  entry.last_heard = now;
  ++version_;
  return outcome;
}

bool MembershipTable::OnHeartbeat(NodeId id, uint64_t incarnation, Clock::time_point now) {
  auto it = members_.find(id);
  if (it == members_.end() || it->second.member.incarnation() != incarnation) return false;
  it->second.last_heard = now;
  return true;
}

bool MembershipTable::OnGoodbye(NodeId id) {
  if (members_.erase(id) == 0) return false;
  ++version_;
  return true;
}

std::vector<NodeId> MembershipTable::ExpireSilent(Clock::time_point now) {
  std::vector<NodeId> expired;
  for (auto it = members_.begin(); it != members_.end();) {
    if (now - it->second.last_heard > options_.Timeout()) {
      expired.push_back(it->first);
      it = members_.erase(it);
    } else {
      ++it;
    }
  }
  if (!expired.empty()) ++version_;
  return expired;
}

wire::MemberList MembershipTable::ToWire() const {
  wire::MemberList list;
  list.set_version(version_);
  for (const auto& [id, entry] : members_) *list.add_members() = entry.member;
  return list;
}

}  // namespace sandtable::coordinator
