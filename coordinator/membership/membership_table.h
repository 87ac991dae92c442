// MembershipTable: who is in the site, decided from hellos, heartbeats, goodbyes and silence.
//
// A node is a member from its Hello until its Goodbye or until it has been silent for
// heartbeat_period * misses_allowed (declared dead). A Hello from a known id replaces the
// entry (restart: new incarnation, maybe new endpoints): one entry per id, never two. Every
// change bumps version(). Pure logic, no sockets, no clock of its own (times are passed in),
// so tests drive it directly. Not thread-safe.
//
// Bounds (docs/reliability.md): at most max_members members (a site's size is known;
// --max-members); every field that is stored and re-published in the member list is checked by
// CheckHello() (endpoint, capability names and sizes), so the member list stays far below the
// codec's message limit (max_members x ~600 bytes).
//
// Binding: a member is bound to the connection (ROUTER routing id) its Hello came on and to
// its incarnation. Heartbeats and Goodbyes count only from that connection and incarnation: a
// process claiming another's id cannot keep it alive or take it off the list. A Hello for a
// bound id from another connection is refused while the bound connection is still up
// (`still_connected`, asked by the server); once it is gone (the node reconnected, or was
// restarted) the new connection takes the id.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "proto/membership.pb.h"

namespace sandtable::coordinator {

using Clock = std::chrono::steady_clock;

// Limits of what a Hello may carry (the member list re-publishes them).
constexpr int kDefaultMaxMembers = 256;          // --max-members
constexpr int kMaxMembersLimit = 4096;           // largest --max-members accepted
constexpr size_t kMaxEndpointBytes = 256;        // Endpoints.peer_router
constexpr size_t kMaxCapabilityNameBytes = 64;   // projector_output, camera_input
constexpr size_t kMaxSoftwareVersionBytes = 64;  // Hello.software_version
constexpr uint32_t kMaxCapabilitySize_px = 65536;
constexpr double kMaxFrameRate_hz = 10000.0;

struct MembershipOptions {
  std::chrono::milliseconds heartbeat_period{100};
  int misses_allowed = 5;  // dead after heartbeat_period * misses_allowed of silence
  int max_members = kDefaultMaxMembers;

  std::chrono::milliseconds Timeout() const { return heartbeat_period * misses_allowed; }
  Status Check() const;
};

// OK when every field of `hello` is within the limits above; else INVALID_ARGUMENT naming the
// field, its size and the limit.
Status CheckHello(const wire::Hello& hello);

enum class HelloOutcome {
  kJoined,           // a new member
  kRestarted,        // a known id with a new incarnation (entry replaced)
  kRepeated,         // the same member again (its HelloAck was lost)
  kReconnected,      // the same member on a new connection (the old one is gone)
  kSiteFull,         // refused: max_members members already
  kIdInUse,          // refused: the id is bound to another connection that is still up
  kConnectionInUse,  // refused: this connection already holds another member id
};
bool Accepted(HelloOutcome outcome);

enum class GoodbyeOutcome { kLeft, kUnknown, kForged };

class MembershipTable {
 public:
  using StillConnected = std::function<bool(const std::string& routing_id)>;

  explicit MembershipTable(MembershipOptions options) : options_(options) {}

  // `hello` must have passed CheckHello(). `routing_id` is the connection it came on.
  HelloOutcome OnHello(NodeId id, const wire::Hello& hello, const std::string& routing_id,
                       Clock::time_point now, const StillConnected& still_connected);
  // True when `id` is a member of this incarnation on this connection (its silence timer
  // restarts); false asks the sender to Hello again (unknown to us, e.g. after a coordinator
  // restart, or a new connection).
  bool OnHeartbeat(NodeId id, uint64_t incarnation, const std::string& routing_id,
                   Clock::time_point now);
  // kLeft when `id` was a member and the Goodbye came from its connection and incarnation.
  GoodbyeOutcome OnGoodbye(NodeId id, uint64_t incarnation, const std::string& routing_id);
  // Removes members silent for longer than the timeout; returns their ids.
  std::vector<NodeId> ExpireSilent(Clock::time_point now);

  bool Contains(NodeId id) const { return members_.count(id) > 0; }
  // True when `id` is a member whose connection is `routing_id` (a message from it is the
  // member's own, not another client's claim).
  bool IsMemberConnection(NodeId id, const std::string& routing_id) const;
  // When the member was last heard (Hello or heartbeat); nullopt for a non-member.
  std::optional<Clock::time_point> LastHeard(NodeId id) const;
  // What came from a member on its connection (any request: heartbeats, status, asks), counted
  // by the server as it takes each off the socket; a message from another connection claiming
  // the id, or from a non-member, is not counted. A restarted member starts from zero.
  struct LinkCounts {
    uint64_t messages_in = 0, bytes_in = 0;
  };
  void CountReceived(NodeId id, const std::string& routing_id, size_t wire_bytes);
  std::optional<LinkCounts> Link(NodeId id) const;
  size_t size() const { return members_.size(); }
  uint64_t version() const { return version_; }
  const MembershipOptions& options() const { return options_; }
  // Sorted by node id. joined_time_ns is on the steady clock of this process.
  wire::MemberList ToWire() const;

 private:
  struct Entry {
    wire::Member member;
    std::string routing_id;
    Clock::time_point last_heard;
    LinkCounts link;
  };
  MembershipOptions options_;
  void Erase(std::map<NodeId, Entry>::iterator it);
  std::map<NodeId, Entry> members_;
  std::map<std::string, NodeId> by_connection_;
  uint64_t version_ = 0;
};

}  // namespace sandtable::coordinator
