#include "coordinator/membership/membership_table.h"

#include <cmath>
#include <string>

namespace sandtable::coordinator {
namespace {

Status CheckText(const std::string& value, size_t limit, const char* field) {
  if (value.size() > limit) {
    return InvalidArgumentError("hello: " + std::string(field) + " of " +
                                std::to_string(value.size()) + " bytes exceeds " +
                                std::to_string(limit) + " bytes");
  }
  return OkStatus();
}

Status CheckSize(uint32_t value_px, const char* field) {
  if (value_px > kMaxCapabilitySize_px) {
    return InvalidArgumentError("hello: capabilities." + std::string(field) + " = " +
                                std::to_string(value_px) + " exceeds " +
                                std::to_string(kMaxCapabilitySize_px) + " px");
  }
  return OkStatus();
}

}  // namespace

Status MembershipOptions::Check() const {
  if (heartbeat_period.count() <= 0) {
    return InvalidArgumentError("membership: heartbeat_period must be > 0 ms");
  }
  if (misses_allowed < 1) {
    return InvalidArgumentError("membership: misses_allowed = " + std::to_string(misses_allowed) +
                                " must be >= 1");
  }
  if (max_members < 1 || max_members > kMaxMembersLimit) {
    return InvalidArgumentError("membership: max_members = " + std::to_string(max_members) +
                                " must be in 1.." + std::to_string(kMaxMembersLimit));
  }
  return OkStatus();
}

Status CheckHello(const wire::Hello& hello) {
  const std::string& endpoint = hello.endpoints().peer_router();
  ST_RETURN_IF_ERROR(CheckText(endpoint, kMaxEndpointBytes, "endpoints.peer_router"));
  if (!endpoint.empty()) {
    const bool transport = endpoint.rfind("tcp://", 0) == 0 || endpoint.rfind("ipc://", 0) == 0;
    bool printable = true;
    for (const char c : endpoint) printable = printable && c > ' ' && c < 127 && c != '*';
    if (!transport || !printable) {
      return InvalidArgumentError(
          "hello: endpoints.peer_router is not a tcp:// or ipc:// endpoint of printable "
          "characters without wildcards");
    }
  }
  const wire::Capabilities& c = hello.capabilities();
  ST_RETURN_IF_ERROR(
      CheckText(c.projector_output(), kMaxCapabilityNameBytes, "capabilities.projector_output"));
  ST_RETURN_IF_ERROR(
      CheckText(c.camera_input(), kMaxCapabilityNameBytes, "capabilities.camera_input"));
  ST_RETURN_IF_ERROR(
      CheckText(hello.software_version(), kMaxSoftwareVersionBytes, "software_version"));
  ST_RETURN_IF_ERROR(CheckSize(c.projector_width_px(), "projector_width_px"));
  ST_RETURN_IF_ERROR(CheckSize(c.projector_height_px(), "projector_height_px"));
  ST_RETURN_IF_ERROR(CheckSize(c.camera_width_px(), "camera_width_px"));
  ST_RETURN_IF_ERROR(CheckSize(c.camera_height_px(), "camera_height_px"));
  if (!std::isfinite(c.frame_rate_hz()) || c.frame_rate_hz() < 0.0 ||
      c.frame_rate_hz() > kMaxFrameRate_hz) {
    return InvalidArgumentError("hello: capabilities.frame_rate_hz must be finite in [0, " +
                                std::to_string(kMaxFrameRate_hz) + "]");
  }
  if (c.camera_bit_depth() > 64) {
    return InvalidArgumentError("hello: capabilities.camera_bit_depth must be <= 64");
  }
  // Unknown fields would be re-published with the member: refuse them too.
  if (!hello.GetReflection()->GetUnknownFields(hello).empty() ||
      !c.GetReflection()->GetUnknownFields(c).empty() ||
      !hello.endpoints().GetReflection()->GetUnknownFields(hello.endpoints()).empty()) {
    return InvalidArgumentError("hello: carries fields this build does not know");
  }
  return OkStatus();
}

bool Accepted(HelloOutcome outcome) {
  return outcome != HelloOutcome::kSiteFull && outcome != HelloOutcome::kIdInUse &&
         outcome != HelloOutcome::kConnectionInUse;
}

void MembershipTable::Erase(std::map<NodeId, Entry>::iterator it) {
  auto bound = by_connection_.find(it->second.routing_id);
  if (bound != by_connection_.end() && bound->second == it->first) by_connection_.erase(bound);
  members_.erase(it);
}

HelloOutcome MembershipTable::OnHello(NodeId id, const wire::Hello& hello,
                                      const std::string& routing_id, Clock::time_point now,
                                      const StillConnected& still_connected) {
  if (auto held = by_connection_.find(routing_id);
      held != by_connection_.end() && held->second != id) {
    return HelloOutcome::kConnectionInUse;
  }
  auto it = members_.find(id);
  if (it != members_.end() && it->second.routing_id != routing_id &&
      (!still_connected || still_connected(it->second.routing_id))) {
    return HelloOutcome::kIdInUse;
  }
  if (it != members_.end() && it->second.member.incarnation() == hello.incarnation()) {
    // The same process saying hello again (its HelloAck was lost, or it reconnected):
    // nothing of the member changes.
    it->second.last_heard = now;
    if (it->second.routing_id == routing_id) return HelloOutcome::kRepeated;
    by_connection_.erase(it->second.routing_id);
    it->second.routing_id = routing_id;
    by_connection_[routing_id] = id;
    return HelloOutcome::kReconnected;
  }
  if (it == members_.end() && members_.size() >= static_cast<size_t>(options_.max_members)) {
    return HelloOutcome::kSiteFull;
  }
  const HelloOutcome outcome =
      it == members_.end() ? HelloOutcome::kJoined : HelloOutcome::kRestarted;
  if (it != members_.end()) by_connection_.erase(it->second.routing_id);
  by_connection_[routing_id] = id;
  Entry& entry = members_[id];
  entry.member.Clear();
  entry.member.set_node_id(id);
  entry.member.set_incarnation(hello.incarnation());
  *entry.member.mutable_endpoints() = hello.endpoints();
  *entry.member.mutable_capabilities() = hello.capabilities();
  entry.member.set_joined_time_ns(
      std::chrono::duration_cast<std::chrono::nanoseconds>(now.time_since_epoch()).count());
  entry.routing_id = routing_id;
  entry.last_heard = now;
  entry.link = LinkCounts{};
  ++version_;
  return outcome;
}

bool MembershipTable::OnHeartbeat(NodeId id, uint64_t incarnation, const std::string& routing_id,
                                  Clock::time_point now) {
  auto it = members_.find(id);
  if (it == members_.end() || it->second.member.incarnation() != incarnation ||
      it->second.routing_id != routing_id) {
    return false;
  }
  it->second.last_heard = now;
  return true;
}

GoodbyeOutcome MembershipTable::OnGoodbye(NodeId id, uint64_t incarnation,
                                          const std::string& routing_id) {
  auto it = members_.find(id);
  if (it == members_.end()) return GoodbyeOutcome::kUnknown;
  if (it->second.member.incarnation() != incarnation || it->second.routing_id != routing_id) {
    return GoodbyeOutcome::kForged;
  }
  Erase(it);
  ++version_;
  return GoodbyeOutcome::kLeft;
}

std::vector<NodeId> MembershipTable::ExpireSilent(Clock::time_point now) {
  std::vector<NodeId> expired;
  for (auto it = members_.begin(); it != members_.end();) {
    if (now - it->second.last_heard > options_.Timeout()) {
      expired.push_back(it->first);
      Erase(it++);
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

bool MembershipTable::IsMemberConnection(NodeId id, const std::string& routing_id) const {
  auto it = members_.find(id);
  return it != members_.end() && it->second.routing_id == routing_id;
}

void MembershipTable::CountReceived(NodeId id, const std::string& routing_id, size_t wire_bytes) {
  auto it = members_.find(id);
  if (it == members_.end() || it->second.routing_id != routing_id) return;
  ++it->second.link.messages_in;
  it->second.link.bytes_in += wire_bytes;
}

std::optional<MembershipTable::LinkCounts> MembershipTable::Link(NodeId id) const {
  auto it = members_.find(id);
  if (it == members_.end()) return std::nullopt;
  return it->second.link;
}

std::optional<Clock::time_point> MembershipTable::LastHeard(NodeId id) const {
  auto it = members_.find(id);
  if (it == members_.end()) return std::nullopt;
  return it->second.last_heard;
}

}  // namespace sandtable::coordinator
