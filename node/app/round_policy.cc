#include "node/app/round_policy.h"

#include <algorithm>

namespace sandtable::node {
namespace {

bool Contains(const std::vector<NodeId>& ids, NodeId id) {
  return std::find(ids.begin(), ids.end(), id) != ids.end();
}

RoundDecision Decide(RoundAction action, std::string why, bool transient = false) {
  RoundDecision d;
  d.action = action;
  d.why = std::move(why);
  d.transient = transient;
  return d;
}

std::string Unit(NodeId id) { return "unit " + std::to_string(id); }

wire::CalibrationState StateOf(const RoundView& v, NodeId id) {
  for (const RoundMember& m : v.members) {
    if (m.id == id) return m.state;
  }
  return wire::CALIBRATION_STATE_UNSPECIFIED;
}

// Members that were not in the last round, or left it and are back, linked, without a
// calibration; a member whose saved calibration held its check is not joining.
std::vector<NodeId> JoiningMembers(const RoundView& v, const std::vector<NodeId>& ids) {
  std::vector<NodeId> joining;
  for (NodeId m : ids) {
    const bool new_member = !Contains(v.last_round_members, m);
    const bool came_back = v.departed.count(m) &&
                           StateOf(v, m) != wire::CALIBRATION_STATE_CALIBRATED &&
                           std::any_of(v.members.begin(), v.members.end(),
                                       [&](const RoundMember& r) { return r.id == m && r.linked; });
    if ((new_member || came_back) && StateOf(v, m) != wire::CALIBRATION_STATE_VERIFIED) {
      joining.push_back(m);
    }
  }
  return joining;
}

}  // namespace

Status RoundPolicyOptions::Check() const {
  if (settle.count() < 0 || join_wait.count() < 0 || expect_wait.count() < 0 ||
      expected_units < 0) {
    return InvalidArgumentError(
        "round policy: settle, join_wait, expect_wait and expected_units must be >= 0");
  }
  return OkStatus();
}

const char* RoundActionName(RoundAction action) {
  switch (action) {
    case RoundAction::kNone:
      return "none";
    case RoundAction::kWait:
      return "wait";
    case RoundAction::kRound:
      return "round";
    case RoundAction::kJoinRound:
      return "join round";
  }
  return "?";
}

RoundDecision DecideRound(const RoundView& v, const RoundPolicyOptions& options) {
  if (!v.has_camera) return Decide(RoundAction::kNone, "no camera");
  if (!v.registered) return Decide(RoundAction::kNone, "not registered", true);
  if (v.round_running) return Decide(RoundAction::kWait, "its round is running", true);
  if (!v.has_member_list) return Decide(RoundAction::kWait, "no member list yet", true);
  if (v.members.empty()) return Decide(RoundAction::kNone, "no member has a projector and camera");
  std::vector<NodeId> ids;
  for (const RoundMember& m : v.members) ids.push_back(m.id);
  const bool lowest = ids.front() == v.self;
  const bool site_runner = v.ran_round && v.holds_site_solution;
  // Who decides for a unit calibrated by another runner: that runner while it is a member.
  const bool runner_gone =
      v.calibrated && !v.ran_round && v.calibrated_by != v.self && !Contains(ids, v.calibrated_by);
  if (!lowest && !site_runner) {
    return Decide(RoundAction::kNone, Unit(ids.front()) + " runs the rounds (the lowest id)");
  }
  if (v.member_list_age < options.settle) {
    return Decide(RoundAction::kWait, "the member list changed less than settle ago", true);
  }
  bool checking = false, all_hold = true, peer_calibrated = false;
  std::vector<NodeId> uncalibrated;
  for (const RoundMember& m : v.members) {
    checking |=
        m.state == wire::CALIBRATION_STATE_SAVED || m.state == wire::CALIBRATION_STATE_VERIFYING;
    all_hold &= m.state == wire::CALIBRATION_STATE_VERIFIED;
    peer_calibrated |= m.id != v.self && m.state == wire::CALIBRATION_STATE_CALIBRATED;
    if (m.state != wire::CALIBRATION_STATE_CALIBRATED &&
        m.state != wire::CALIBRATION_STATE_VERIFIED) {
      uncalibrated.push_back(m.id);
    }
  }
  if (checking) return Decide(RoundAction::kWait, "a member is checking its saved calibration");
  RoundDecision out;
  out.saw_calibrated_peer = peer_calibrated;
  out.saw_uncalibrated_member = !uncalibrated.empty();
  std::vector<NodeId> joining;
  if (v.ran_round || v.calibrated) {
    if (!v.ran_round && !runner_gone) {
      out.action = RoundAction::kNone;
      out.why = "calibrated by " + Unit(v.calibrated_by) + ", which decides";
      return out;
    }
    if (runner_gone) {
      // Its runner left: a member without a calibration is calibrated with all again (no
      // unit here holds the site's solution to hold it against).
      if (uncalibrated.empty()) {
        out.action = RoundAction::kNone;
        out.why =
            "every member holds a calibration (its runner, " + Unit(v.calibrated_by) + ", left)";
        return out;
      }
      const RoundClock::time_point first = v.first_seen_uncalibrated_member.value_or(v.now);
      if (v.now - first < options.join_wait) {
        out.action = RoundAction::kWait;
        out.why = Unit(uncalibrated.front()) + " holds no calibration and its site's runner (" +
                  Unit(v.calibrated_by) + ") left; waiting join_wait before calibrating all";
        return out;
      }
      out.why = "the site's runner (" + Unit(v.calibrated_by) +
                ") left and units joined; calibrating all again";
    } else {
      joining = JoiningMembers(v, ids);
      if (joining.empty()) {
        out.action = RoundAction::kNone;
        out.why = "every member was in the last round";
        return out;
      }
      // A site solved from one unit's view alone is weak (its depth rests on one short factory
      // baseline); units that join it calibrate all again. So do units that outnumber the
      // site they join: a join round places them against the held units, and far from those
      // it cannot.
      const bool weak_site = site_runner && (v.site_units < 2 || joining.size() > v.site_units);
      if (weak_site) {
        out.why = std::to_string(joining.size()) + " unit(s) joined a site solved from " +
                  std::to_string(v.site_units) + "; calibrating all again";
        joining.clear();
      } else if (site_runner) {
        out.why = std::to_string(joining.size()) +
                  " unit(s) joined the calibrated site; calibrating them against it";
      } else {
        out.why =
            "units joined after the last round, whose site was not solved; calibrating "
            "all again";
        joining.clear();
      }
    }
  } else if (peer_calibrated) {
    const RoundClock::time_point first = v.first_seen_calibrated_peer.value_or(v.now);
    if (v.now - first < options.join_wait) {
      out.action = RoundAction::kWait;
      out.why = "the other units are calibrated; waiting join_wait for their runner's join round";
      return out;
    }
    if (v.last_step_from_other && v.now - *v.last_step_from_other < options.join_wait) {
      out.action = RoundAction::kWait;
      out.why = "another unit's round is calibrating this unit";
      return out;
    }
    out.why =
        "the other units are calibrated and their runner did not calibrate this unit; "
        "calibrating all";
  } else if (all_hold) {
    out.action = RoundAction::kNone;
    out.why = "every unit's saved calibration held its check";
    return out;
  }
  for (const RoundMember& m : v.members) {
    if (!m.linked) {
      out.action = RoundAction::kWait;
      out.why = Unit(m.id) + " is not linked yet (no heartbeat)";
      return out;
    }
  }
  if (!v.ran_round && !v.calibrated && options.expected_units > 0 &&
      static_cast<int>(ids.size()) < options.expected_units) {
    const bool waited = v.now - v.started >= options.expect_wait;
    out.why = std::to_string(ids.size()) + " of " + std::to_string(options.expected_units) +
              " expected units are members; " +
              (waited ? "waited long enough, starting" : "waiting for the others");
    if (!waited) {
      out.action = RoundAction::kWait;
      return out;
    }
  }
  out.members = ids;
  if (!joining.empty()) {
    out.action = RoundAction::kJoinRound;
    out.projecting = joining;
  } else {
    out.action = RoundAction::kRound;
    out.projecting = ids;
    if (out.why.empty()) out.why = "calibrating every member";
  }
  return out;
}

}  // namespace sandtable::node
