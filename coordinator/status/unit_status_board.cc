#include "coordinator/status/unit_status_board.h"

#include <cmath>

#include <nlohmann/json.hpp>

namespace sandtable::coordinator {
namespace {

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

}  // namespace

Status CheckUnitStatus(const wire::UnitStatus& s) {
  if (s.footprint_m_size() > kMaxFootprintPoints) {
    return InvalidArgumentError("unit status: " + std::to_string(s.footprint_m_size()) +
                                " footprint points (at most " +
                                std::to_string(kMaxFootprintPoints) + ")");
  }
  for (const wire::Vector2& p : s.footprint_m()) {
    if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || std::abs(p.x()) > 1e3 ||
        std::abs(p.y()) > 1e3) {
      return InvalidArgumentError("unit status: a footprint point is not finite or over 1 km");
    }
  }
  for (const double v :
       {s.predicted_rms_mm(), s.projector_rms_px(), s.frame_ms_p50(), s.frame_ms_p99()}) {
    if (!std::isfinite(v) || v < 0.0) {
      return InvalidArgumentError("unit status: a figure is negative or not finite");
    }
  }
  for (const std::string* text : {&s.phase(), &s.host_name(), &s.pattern(), &s.last_error()}) {
    if (text->size() > kMaxStatusTextChars) {
      return InvalidArgumentError("unit status: a text over " +
                                  std::to_string(kMaxStatusTextChars) + " characters");
    }
  }
  if (s.neighbours_size() > static_cast<int>(kMaxBoardUnits)) {
    return InvalidArgumentError("unit status: too many neighbours");
  }
  return OkStatus();
}

Status UnitStatusBoard::Update(NodeId id, const std::string& routing_id,
                               const wire::UnitStatus& status, const MembershipTable& members,
                               Clock::time_point now) {
  if (!members.IsMemberConnection(id, routing_id)) {
    ++refused_;
    return Status(StatusCode::kPermissionDenied,
                  "unit status for node " + std::to_string(id) +
                      " from a connection that is not that member's");
  }
  if (Status valid = CheckUnitStatus(status); !valid.ok()) {
    ++refused_;
    return valid;
  }
  if (!units_.count(id) && units_.size() >= kMaxBoardUnits) {
    ++refused_;
    return InvalidArgumentError("unit status: the board is full");
  }
  Entry& e = units_[id];
  e.status = status;
  e.has_status = true;
  e.lost_since.reset();
  const std::string state = ConsoleState(id, members, now);
  if (state != e.state) {
    e.state = state;
    e.state_since = now;
  }
  return OkStatus();
}

void UnitStatusBoard::Sweep(const MembershipTable& members, Clock::time_point now) {
  const wire::MemberList list = members.ToWire();
  for (const wire::Member& m : list.members()) {
    if (!units_.count(m.node_id()) && units_.size() < kMaxBoardUnits) units_[m.node_id()];
  }
  for (auto it = units_.begin(); it != units_.end();) {
    Entry& e = it->second;
    if (!members.Contains(it->first) && !e.lost_since) e.lost_since = now;
    if (e.lost_since && now - *e.lost_since > kLostKeptFor) {
      it = units_.erase(it);
      continue;
    }
    const std::string state = ConsoleState(it->first, members, now);
    if (state != e.state) {
      e.state = state;
      e.state_since = now;
    }
    ++it;
  }
}

std::string UnitStatusBoard::ConsoleState(NodeId id, const MembershipTable& members,
                                          Clock::time_point now) const {
  auto it = units_.find(id);
  if (!members.Contains(id)) return it == units_.end() ? "" : "lost";
  const std::optional<Clock::time_point> heard = members.LastHeard(id);
  if (heard && now - *heard > kStalledAfterPeriods * members.options().heartbeat_period) {
    return "stalled";
  }
  if (it == units_.end() || !it->second.has_status) return "discovered";
  const wire::UnitStatus& s = it->second.status;
  // A unit calibrated again says so while its new round runs.
  if (s.phase() == "calibrating") return "calibrating";
  // A unit without self-calibration (a held calibration) says only its phase.
  const bool unspecified = s.calibration_state() == wire::CALIBRATION_STATE_UNSPECIFIED;
  if (s.calibration_state() == wire::CALIBRATION_STATE_CALIBRATED ||
      (unspecified && s.phase() == "calibrated")) {
    return s.blended() ? "blending" : "calibrated";
  }
  if (s.calibration_state() == wire::CALIBRATION_STATE_VERIFIED) {
    return s.blended() ? "blending" : "verified";
  }
  // A unit that says what keeps it from calibrating ("failed", "no camera", ...) has failed.
  const bool stuck =
      s.phase() != "calibrating" && s.phase() != "starting" && !s.last_error().empty();
  return s.phase() == "failed" || stuck ? "failed" : "calibrating";
}

nlohmann::json UnitStatusBoard::Json(const MembershipTable& members, Clock::time_point now) const {
  using nlohmann::json;
  json units = json::array();
  for (const auto& [id, e] : units_) {
    const wire::UnitStatus& s = e.status;
    json footprint = json::array();
    for (const wire::Vector2& p : s.footprint_m()) footprint.push_back({p.x(), p.y()});
    const std::optional<Clock::time_point> heard = members.LastHeard(id);
    const std::optional<MembershipTable::LinkCounts> link = members.Link(id);
    const std::string state = ConsoleState(id, members, now);
    const Clock::time_point since =
        state == e.state ? e.state_since : (e.lost_since ? *e.lost_since : now);
    units.push_back(
        {{"node_id", id},
         {"state", state},
         {"since_s", Seconds(now - since)},
         {"heartbeat_age_s", heard ? json(Seconds(now - *heard)) : json(nullptr)},
         {"link", link ? json{{"messages_in", link->messages_in}, {"bytes_in", link->bytes_in}}
                       : json(nullptr)},
         {"host_name", s.host_name()},
         {"calibration_state", wire::CalibrationState_Name(s.calibration_state())},
         {"phase", e.has_status ? s.phase() : std::string("discovered")},
         {"footprint_m", footprint},
         {"predicted_rms_mm", s.predicted_rms_mm()},
         {"projector_rms_px", s.projector_rms_px()},
         {"round", s.round()},
         {"frame_ms_p50", s.frame_ms_p50()},
         {"frame_ms_p99", s.frame_ms_p99()},
         {"pattern", s.pattern()},
         {"blended", s.blended()},
         {"neighbours", json(std::vector<uint32_t>(s.neighbours().begin(), s.neighbours().end()))},
         {"last_error", s.last_error()}});
  }
  return units;
}

}  // namespace sandtable::coordinator
