// MembershipTable: who is in the site, decided from hellos, heartbeats, goodbyes and silence.
//
// A node is a member from its Hello until its Goodbye or until it has been silent for
// heartbeat_period * misses_allowed (declared dead). A Hello from a known id replaces the
// entry (restart: new incarnation, maybe new endpoints): one entry per id, never two. Every
// change bumps version(). Pure logic, no sockets, no clock of its own (times are passed in),
// so tests drive it directly. Not thread-safe.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <vector>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "proto/membership.pb.h"

namespace sandtable::coordinator {

using Clock = std::chrono::steady_clock;

struct MembershipOptions {
  std::chrono::milliseconds heartbeat_period{100};
  int misses_allowed = 5;  // dead after heartbeat_period * misses_allowed of silence

  std::chrono::milliseconds Timeout() const { return heartbeat_period * misses_allowed; }
  Status Check() const;
};

enum class HelloOutcome { kJoined, kRestarted, kRepeated };

class MembershipTable {
 public:
  explicit MembershipTable(MembershipOptions options) : options_(options) {}

  HelloOutcome OnHello(NodeId id, const wire::Hello& hello, Clock::time_point now);
  // True when `id` is a member of this incarnation (its silence timer restarts); false asks
  // the sender to Hello again (unknown to us, e.g. after a coordinator restart).
  bool OnHeartbeat(NodeId id, uint64_t incarnation, Clock::time_point now);
  // True when `id` was a member.
  bool OnGoodbye(NodeId id);
  // Removes members silent for longer than the timeout; returns their ids.
  std::vector<NodeId> ExpireSilent(Clock::time_point now);

  bool Contains(NodeId id) const { return members_.count(id) > 0; }
  size_t size() const { return members_.size(); }
  uint64_t version() const { return version_; }
  // Sorted by node id. joined_time_ns is on the steady clock of this process.
  wire::MemberList ToWire() const;

 private:
  struct Entry {
    wire::Member member;
    Clock::time_point last_heard;
  };
  MembershipOptions options_;
  std::map<NodeId, Entry> members_;
  uint64_t version_ = 0;
};

}  // namespace sandtable::coordinator
