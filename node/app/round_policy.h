// RoundPolicy: whether a unit starts a self-calibration round now, and which (docs/calibration.md,
// "Who runs a round"). A pure function of what the unit knows: the member list and each
// member's calibration state and link, the rounds it ran, the calibration it holds and who gave
// it, clocks. CalibrationRunner (calibration_runner.h) gathers the view, asks, and carries the
// decision out; the table-driven tests in tests/node/app/round_policy_test.cc cover every
// branch.
//
// The rules, in order:
//   - No camera, not registered, or no member list: nothing. A round of its own still running:
//     wait.
//   - The runner is the lowest id among the members with a projector and a camera; a unit
//     that ran the round that calibrated the site (it holds the site's solution) stays its
//     runner for units that join later, whatever its id.
//   - Nothing until the member list has not changed for `settle`, nor while a member checks a
//     saved calibration.
//   - An operator's ask to calibrate again (RoundView::asked) comes before the rules below:
//     the whole site, or one unit against the others held (a join round) when this unit holds
//     the site's solution with at least two other units in it, else the whole site. It waits
//     for the unit's own round and for every member to be linked; a unit that is not the
//     runner (or calibrated by a runner still present) drops it as not its own.
//   - After a round: a new one only for members that joined since (not in it, or left it and
//     came back without a calibration) and hold no checked calibration. The site's runner
//     calibrates them against the held site (a join round) unless the site is weak (solved
//     from one unit, or fewer units than join it): then, like a runner without the site's
//     solution, all again.
//   - A unit calibrated by another runner leaves the decisions to that runner while it is a
//     member. When that runner is gone and this unit is the lowest id, it takes over: a member
//     without a calibration (a unit that joined after the runner left) is calibrated with all
//     the others again, once join_wait has passed since it was first seen.
//   - The lowest id of a site whose other units are calibrated waits join_wait for their
//     runner's join round before it runs one itself (that runner may have left), and goes on
//     waiting while that round sends it steps (a join round can take longer than join_wait;
//     a second round started beside it would clobber both).
//   - A round that left members it was to calibrate without a calibration (its solve failed, or
//     it left them out) is tried again for them, retry_wait after it ended, the wait doubling
//     with each round in a row that failed, at most max_retries times; then the runner gives
//     up and says so (an operator's ask starts it again).
//   - Every saved calibration held its check: no round.
//   - Every member must be linked (a heartbeat came), and with expected_units, that many must
//     be members or expect_wait must have passed since the unit started.
#pragma once

#include <chrono>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "proto/envelope.pb.h"

namespace sandtable::node {

using RoundClock = std::chrono::steady_clock;

// An operator's ask to calibrate again (the coordinator's recalibrate_ask), not carried out yet.
struct RecalibrationAsk {
  uint64_t id = 0;
  bool all_units = true;
  NodeId unit = kInvalidNodeId;  // when !all_units
};

struct RoundMember {
  NodeId id = kInvalidNodeId;
  wire::CalibrationState state = wire::CALIBRATION_STATE_UNSPECIFIED;
  bool linked = false;  // this unit itself, or a peer whose heartbeat came
};

// What a unit knows when it asks (CalibrationRunner::RoundViewNow).
struct RoundView {
  NodeId self = kInvalidNodeId;
  bool has_camera = false;
  bool registered = false;
  bool has_member_list = false;
  std::vector<RoundMember> members;  // with a projector and a camera, by increasing id
  RoundClock::time_point now{};
  RoundClock::duration member_list_age{};
  // This unit's last round as runner.
  bool round_running = false;         // started and not finished
  bool ran_round = false;             // one finished
  bool holds_site_solution = false;   // that round solved the site
  size_t site_units = 0;              // units in the site's solution (joined ones included)
  std::vector<NodeId> site_unit_ids;  // ... which
  std::vector<NodeId> last_round_members;
  std::set<NodeId> departed;  // units the last round left out because they left
  // Rounds in a row that left a unit they were to calibrate without a calibration (0: the last
  // one placed every unit it was to), and when the last round ended.
  int failed_rounds = 0;
  std::optional<RoundClock::time_point> last_round_ended;
  // This unit's calibration from another unit's round, and who ran it.
  bool calibrated = false;
  NodeId calibrated_by = kInvalidNodeId;
  std::optional<RoundClock::time_point> first_seen_calibrated_peer;
  // The last calibration step another unit's round sent this one: it is being calibrated.
  std::optional<RoundClock::time_point> last_step_from_other;
  std::optional<RoundClock::time_point> first_seen_uncalibrated_member;
  RoundClock::time_point started{};  // the service's creation
  std::optional<RecalibrationAsk> asked;
};

struct RoundPolicyOptions {
  RoundClock::duration settle = std::chrono::milliseconds(1500);
  RoundClock::duration join_wait = std::chrono::seconds(15);
  int expected_units = 0;  // 0: any number
  RoundClock::duration expect_wait = std::chrono::seconds(180);
  RoundClock::duration retry_wait = std::chrono::seconds(30);
  int max_retries = 3;
  // INVALID_ARGUMENT: a negative duration, expected_units or max_retries.
  Status Check() const;
};

enum class RoundAction {
  kNone,       // nothing to do: not this unit's decision, or nothing to calibrate
  kWait,       // not yet: ask again at the next step
  kRound,      // calibrate every member
  kJoinRound,  // calibrate `projecting` against the held site
};
const char* RoundActionName(RoundAction action);

struct RoundDecision {
  RoundAction action = RoundAction::kNone;
  std::vector<NodeId> members;     // kRound, kJoinRound: the round's units
  std::vector<NodeId> projecting;  // ... those calibrated (a join round: the joining units)
  std::string why;                 // in words, for the log
  // A passing state (not registered, no member list yet, the list settling, its own round
  // running): the service logs it at debug level, the rest at info when it changes.
  bool transient = false;
  // What the service keeps for the next ask: a calibrated peer, or a member without a
  // calibration, was seen.
  bool saw_calibrated_peer = false;
  bool saw_uncalibrated_member = false;
  // The operator's ask is answered: a round for it starts, or it is not this unit's to carry
  // out. The runner forgets it; otherwise it asks again with it next step.
  bool ask_done = false;
};

RoundDecision DecideRound(const RoundView& view, const RoundPolicyOptions& options);

}  // namespace sandtable::node
