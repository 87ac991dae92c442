#include "node/app/round_policy.h"

#include <algorithm>
#include <optional>

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

// Members the last round was to calibrate that hold no calibration (it failed them), linked.
std::vector<NodeId> FailedMembers(const RoundView& v) {
  std::vector<NodeId> failed;
  for (const RoundMember& m : v.members) {
    if (Contains(v.last_round_members, m.id) && m.linked &&
        m.state != wire::CALIBRATION_STATE_CALIBRATED &&
        m.state != wire::CALIBRATION_STATE_VERIFIED) {
      failed.push_back(m.id);
    }
  }
  return failed;
}

std::string Units(const std::vector<NodeId>& ids) {
  std::string out;
  for (NodeId id : ids) out += (out.empty() ? "unit " : ", ") + std::to_string(id);
  return out;
}

// After a round that left members without a calibration (RoundView::failed_rounds): a decision
// to wait or give up, or nullopt with `joining` set to the members to try again for and
// `retry` the words that say so (nothing to retry: both untouched).
std::optional<RoundDecision> Retry(const RoundView& v, const RoundPolicyOptions& options,
                                   std::vector<NodeId>* joining, std::string* retry) {
  if (v.failed_rounds <= 0) return std::nullopt;
  const std::vector<NodeId> failed = FailedMembers(v);
  if (failed.empty()) return std::nullopt;
  if (v.failed_rounds > options.max_retries) {
    return Decide(RoundAction::kNone, std::to_string(v.failed_rounds) + " rounds in a row left " +
                                          Units(failed) +
                                          " without a calibration; not trying again (recalibrate "
                                          "from the console)");
  }
  const RoundClock::duration wait = options.retry_wait * (1 << std::min(v.failed_rounds - 1, 10));
  const long wait_s = std::chrono::duration_cast<std::chrono::seconds>(wait).count();
  if (v.last_round_ended && v.now - *v.last_round_ended < wait) {
    return Decide(RoundAction::kWait, "the last round left " + Units(failed) +
                                          " without a calibration; trying again " +
                                          std::to_string(wait_s) + " s after it");
  }
  *joining = failed;
  *retry = "trying again (" + std::to_string(v.failed_rounds) + " of " +
           std::to_string(options.max_retries) + ") for " + Units(failed) + ": ";
  return std::nullopt;
}

// The operator asked to calibrate again (RoundView::asked): this unit is the one that decides.
RoundDecision DecideAsked(const RoundView& v, const std::vector<NodeId>& ids, bool site_runner,
                          bool runner_gone, bool peer_calibrated) {
  const RecalibrationAsk& ask = *v.asked;
  const std::string what = ask.all_units ? std::string("the site") : Unit(ask.unit);
  RoundDecision out;
  out.ask_done = true;
  if (v.calibrated && !v.ran_round && !runner_gone && v.calibrated_by != v.self) {
    out.action = RoundAction::kNone;
    out.why = "calibrated by " + Unit(v.calibrated_by) +
              ", which carries out the operator's recalibration of " + what;
    return out;
  }
  if (!site_runner && !v.calibrated && peer_calibrated) {
    // Not placed itself while others are: their runner holds the site and carries it out (a
    // second round beside its own would clobber both).
    out.action = RoundAction::kNone;
    out.why =
        "other units are calibrated; their runner carries out the operator's "
        "recalibration of " +
        what;
    return out;
  }
  if (!ask.all_units && !Contains(ids, ask.unit)) {
    out.action = RoundAction::kNone;
    out.why = "the operator asked to recalibrate " + what +
              ", which is not a member with a projector and a camera";
    return out;
  }
  for (const RoundMember& m : v.members) {
    if (!m.linked) {
      out.action = RoundAction::kWait;
      out.ask_done = false;
      out.why = "recalibration of " + what + " asked; " + Unit(m.id) +
                " is not linked yet (no heartbeat)";
      return out;
    }
  }
  out.members = ids;
  // One unit against the others: they are held, so at least two must be in the held site.
  const bool in_site =
      std::find(v.site_unit_ids.begin(), v.site_unit_ids.end(), ask.unit) != v.site_unit_ids.end();
  const size_t held = v.site_units - (in_site ? 1 : 0);
  if (!ask.all_units && site_runner && held >= 2) {
    out.action = RoundAction::kJoinRound;
    out.projecting = {ask.unit};
    out.why = "the operator asked to recalibrate " + what + "; calibrating it against the " +
              std::to_string(held) + " other units of the site (held)";
    return out;
  }
  out.action = RoundAction::kRound;
  out.projecting = ids;
  out.why = ask.all_units ? "the operator asked to recalibrate the site; calibrating every member"
                          : "the operator asked to recalibrate " + what +
                                "; no site with two other units is held here to place it "
                                "against, calibrating every member";
  return out;
}

}  // namespace

Status RoundPolicyOptions::Check() const {
  if (settle.count() < 0 || join_wait.count() < 0 || expect_wait.count() < 0 ||
      retry_wait.count() < 0 || expected_units < 0 || max_retries < 0) {
    return InvalidArgumentError(
        "round policy: settle, join_wait, expect_wait, retry_wait, expected_units and "
        "max_retries must be >= 0");
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
    RoundDecision d =
        Decide(RoundAction::kNone, Unit(ids.front()) + " runs the rounds (the lowest id)");
    d.ask_done = v.asked.has_value();
    return d;
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
  if (v.asked) return DecideAsked(v, ids, site_runner, runner_gone, peer_calibrated);
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
      std::string retry;
      if (joining.empty()) {
        if (std::optional<RoundDecision> wait = Retry(v, options, &joining, &retry)) {
          wait->saw_calibrated_peer = out.saw_calibrated_peer;
          wait->saw_uncalibrated_member = out.saw_uncalibrated_member;
          return *wait;
        }
      }
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
        out.why = retry.empty() ? "units joined after the last round, whose site was not "
                                  "solved; calibrating all again"
                                : "the last round solved no site; calibrating all again";
        joining.clear();
      }
      out.why = retry + out.why;
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
