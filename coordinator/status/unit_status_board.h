// UnitStatusBoard: what the coordinator knows of each unit for the operator's console: the
// latest UnitStatus a member sent (proto/membership.proto), its heartbeat's age, and the units
// that were members and are gone ("lost"), kept for kLostKeptFor so an operator sees them go.
//
// The console's state of a unit (ConsoleState): "lost" (was a member, is not), "stalled" (a
// member silent for more than kStalledAfterPeriods heartbeat periods), "discovered" (a member
// that has sent no status yet), "failed" (its last calibration failed and it holds none),
// "calibrating", "verified", "blending" (calibrated and a blend mask shown), "calibrated".
//
// Only the member itself may set its status: a UnitStatus from another connection than the
// member's is refused, as is one over the limits (footprint points, strings, non-finite
// numbers). Used on the coordinator's thread only.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "coordinator/membership/membership_table.h"
#include "proto/membership.pb.h"

namespace sandtable::coordinator {

inline constexpr int kMaxFootprintPoints = 64;
inline constexpr size_t kMaxStatusTextChars = 256;
inline constexpr size_t kMaxBoardUnits = 4096;
inline constexpr std::chrono::minutes kLostKeptFor{10};
inline constexpr int kStalledAfterPeriods = 3;

// OK when `status` is within the limits above (finite numbers, footprint points, strings).
Status CheckUnitStatus(const wire::UnitStatus& status);

class UnitStatusBoard {
 public:
  // A member's status. INVALID_ARGUMENT (nothing kept) for one over the limits, PERMISSION_DENIED
  // for a sender that is not the member on this connection.
  Status Update(NodeId id, const std::string& routing_id, const wire::UnitStatus& status,
                const MembershipTable& members, Clock::time_point now);

  // Marks members that are gone as lost (since `now`), forgets lost units after kLostKeptFor.
  void Sweep(const MembershipTable& members, Clock::time_point now);

  // The console's state of a unit (see the header comment); "" for an unknown one.
  std::string ConsoleState(NodeId id, const MembershipTable& members, Clock::time_point now) const;

  // [{"node_id", "state", "since_s", "heartbeat_age_s", "link": {"messages_in", "bytes_in"}
  // (MembershipTable::Link; null for a unit that is not a member), "host_name", "footprint_m":
  // [[x, y], ...], "predicted_rms_mm", "projector_rms_px", "round", "frame_ms_p50",
  // "frame_ms_p99", "pattern", "blended", "neighbours", "last_error", "calibration_state",
  // "phase"}] sorted by node id: members and lost units.
  nlohmann::json Json(const MembershipTable& members, Clock::time_point now) const;

  size_t size() const { return units_.size(); }
  uint64_t refused() const { return refused_; }

 private:
  struct Entry {
    wire::UnitStatus status;
    bool has_status = false;
    std::string state;  // the last ConsoleState seen by Sweep
    Clock::time_point state_since{};
    std::optional<Clock::time_point> lost_since;
  };
  std::map<NodeId, Entry> units_;
  uint64_t refused_ = 0;
};

}  // namespace sandtable::coordinator
