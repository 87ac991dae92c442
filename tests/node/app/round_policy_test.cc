// The round policy (node/app/round_policy.h), table-driven: one row per situation a unit can be
// in (a first round, a join while a round runs, a runner that dies mid-round or after it, a
// newcomer whose messages are dropped, two newcomers at once, a unit that leaves during its
// join, saved calibrations, an expected site size, an operator's ask to calibrate again, a
// failed round tried again), each with the action and units expected.
#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "node/app/round_policy.h"

namespace sandtable::node {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;
constexpr auto kNone = wire::CALIBRATION_STATE_NONE;
constexpr auto kCalibrated = wire::CALIBRATION_STATE_CALIBRATED;
constexpr auto kSaved = wire::CALIBRATION_STATE_SAVED;
constexpr auto kVerified = wire::CALIBRATION_STATE_VERIFIED;

const RoundClock::time_point kNow = RoundClock::time_point() + seconds(1000);

// A registered unit `self` with a camera whose member list (linked members, no calibration)
// settled long ago, that has run no round.
RoundView Fresh(NodeId self, std::vector<NodeId> ids) {
  RoundView v;
  v.self = self;
  v.has_camera = v.registered = v.has_member_list = true;
  for (NodeId id : ids) v.members.push_back({id, kNone, true});
  v.now = kNow;
  v.member_list_age = seconds(10);
  v.started = kNow - seconds(60);
  return v;
}

void SetState(RoundView* v, NodeId id, wire::CalibrationState state) {
  for (RoundMember& m : v->members) {
    if (m.id == id) m.state = state;
  }
}

// `self` ran the round of `round` and solved the site (every unit of the round calibrated).
RoundView SiteRunner(NodeId self, std::vector<NodeId> round, std::vector<NodeId> now) {
  RoundView v = Fresh(self, now);
  v.ran_round = v.holds_site_solution = true;
  v.last_round_members = round;
  v.site_units = round.size();
  v.site_unit_ids = round;
  v.calibrated = true;
  v.calibrated_by = self;
  for (NodeId id : round) SetState(&v, id, kCalibrated);
  return v;
}

struct Row {
  std::string name;
  std::function<RoundView()> view;
  RoundAction action;
  std::vector<NodeId> members, projecting;  // checked for kRound and kJoinRound
  std::string why;                          // a part of the decision's words
};

TEST(RoundPolicyTest, EveryBranch) {
  RoundPolicyOptions options;  // settle 1.5 s, join_wait 15 s
  RoundPolicyOptions expecting = options;
  expecting.expected_units = 4;
  const std::vector<Row> rows = {
      {"no camera",
       [] {
         RoundView v = Fresh(1, {1, 2});
         v.has_camera = false;
         return v;
       },
       RoundAction::kNone,
       {},
       {},
       "no camera"},
      {"not registered",
       [] {
         RoundView v = Fresh(1, {1, 2});
         v.registered = false;
         return v;
       },
       RoundAction::kNone,
       {},
       {},
       "not registered"},
      {"no member list",
       [] {
         RoundView v = Fresh(1, {});
         v.has_member_list = false;
         return v;
       },
       RoundAction::kWait,
       {},
       {},
       "no member list"},
      {"the first round, by the lowest id",
       [] {
         return Fresh(1, {1, 2, 3});
       },
       RoundAction::kRound,
       {1, 2, 3},
       {1, 2, 3},
       "every member"},
      {"not the lowest id",
       [] {
         return Fresh(2, {1, 2, 3});
       },
       RoundAction::kNone,
       {},
       {},
       "unit 1 runs the rounds"},
      {"the member list just changed",
       [] {
         RoundView v = Fresh(1, {1, 2});
         v.member_list_age = milliseconds(200);
         return v;
       },
       RoundAction::kWait,
       {},
       {},
       "settle"},
      {"a newcomer whose messages are dropped (no heartbeat yet)",
       [] {
         RoundView v = Fresh(1, {1, 2, 3});
         v.members[2].linked = false;
         return v;
       },
       RoundAction::kWait,
       {},
       {},
       "unit 3 is not linked"},
      {"a join while its round runs",
       [] {
         RoundView v = Fresh(1, {1, 2, 3, 4});
         v.round_running = true;
         return v;
       },
       RoundAction::kWait,
       {},
       {},
       "running"},
      {"one newcomer after the round: a join round",
       [] {
         return SiteRunner(1, {1, 2, 3}, {1, 2, 3, 4});
       },
       RoundAction::kJoinRound,
       {1, 2, 3, 4},
       {4},
       "against it"},
      {"two newcomers at once: one join round for both",
       [] {
         return SiteRunner(1, {1, 2, 3}, {1, 2, 3, 4, 5});
       },
       RoundAction::kJoinRound,
       {1, 2, 3, 4, 5},
       {4, 5},
       "2 unit(s) joined"},
      {"a newcomer with a lower id than the site's runner: the runner still decides",
       [] {
         return SiteRunner(2, {2, 3, 4}, {0, 2, 3, 4});
       },
       RoundAction::kJoinRound,
       {0, 2, 3, 4},
       {0},
       "against it"},
      {"newcomers that outnumber the site: all again",
       [] {
         return SiteRunner(1, {1, 2}, {1, 2, 3, 4, 5});
       },
       RoundAction::kRound,
       {1, 2, 3, 4, 5},
       {1, 2, 3, 4, 5},
       "all again"},
      {"a site solved from one unit: all again",
       [] {
         return SiteRunner(1, {1}, {1, 2});
       },
       RoundAction::kRound,
       {1, 2},
       {1, 2},
       "solved from 1"},
      {"a runner whose round failed: all again",
       [] {
         RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3, 4});
         v.holds_site_solution = false;
         v.site_units = 0;
         return v;
       },
       RoundAction::kRound,
       {1, 2, 3, 4},
       {1, 2, 3, 4},
       "not solved"},
      {"nobody new after the round",
       [] {
         return SiteRunner(1, {1, 2, 3}, {1, 2, 3});
       },
       RoundAction::kNone,
       {},
       {},
       "every member was in the last round"},
      {"a unit that left the round comes back without a calibration",
       [] {
         RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3});
         v.departed = {3};
         SetState(&v, 3, kNone);
         return v;
       },
       RoundAction::kJoinRound,
       {1, 2, 3},
       {3},
       "against it"},
      {"a unit that leaves during its join: nothing more until it comes back",
       [] {
         RoundView v = SiteRunner(1, {1, 2, 3, 4}, {1, 2, 3});
         v.departed = {4};
         v.site_units = 3;
         return v;
       },
       RoundAction::kNone,
       {},
       {},
       "every member was in the last round"},
      {"a newcomer whose saved calibration held needs no round",
       [] {
         RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3, 4});
         SetState(&v, 4, kVerified);
         return v;
       },
       RoundAction::kNone,
       {},
       {},
       "every member was in the last round"},
      {"a member checking its saved calibration",
       [] {
         RoundView v = Fresh(1, {1, 2});
         SetState(&v, 2, kSaved);
         return v;
       },
       RoundAction::kWait,
       {},
       {},
       "checking its saved calibration"},
      {"every saved calibration held",
       [] {
         RoundView v = Fresh(1, {1, 2});
         SetState(&v, 1, kVerified);
         SetState(&v, 2, kVerified);
         return v;
       },
       RoundAction::kNone,
       {},
       {},
       "held its check"},
      {"calibrated by a runner that is still a member",
       [] {
         RoundView v = Fresh(1, {1, 2, 3, 4});
         v.calibrated = true;
         v.calibrated_by = 2;
         for (NodeId id : {1, 2, 3}) SetState(&v, id, kCalibrated);
         return v;
       },
       RoundAction::kNone,
       {},
       {},
       "calibrated by unit 2, which decides"},
      {"the runner died mid-round: the next lowest id runs it again",
       [] {
         return Fresh(2, {2, 3, 4});
       },
       RoundAction::kRound,
       {2, 3, 4},
       {2, 3, 4},
       "every member"},
      {"the runner died after the round and a unit joined: wait join_wait first",
       [] {
         RoundView v = Fresh(2, {2, 3, 4});
         v.calibrated = true;
         v.calibrated_by = 1;
         SetState(&v, 2, kCalibrated);
         SetState(&v, 3, kCalibrated);
         v.first_seen_uncalibrated_member = kNow - seconds(3);
         return v;
       },
       RoundAction::kWait,
       {},
       {},
       "its site's runner (unit 1) left"},
      {"the runner died after the round and a unit joined: then all again",
       [] {
         RoundView v = Fresh(2, {2, 3, 4});
         v.calibrated = true;
         v.calibrated_by = 1;
         SetState(&v, 2, kCalibrated);
         SetState(&v, 3, kCalibrated);
         v.first_seen_uncalibrated_member = kNow - seconds(16);
         return v;
       },
       RoundAction::kRound,
       {2, 3, 4},
       {2, 3, 4},
       "left and units joined"},
      {"the runner died after the round, nobody joined",
       [] {
         RoundView v = Fresh(2, {2, 3});
         v.calibrated = true;
         v.calibrated_by = 1;
         SetState(&v, 2, kCalibrated);
         SetState(&v, 3, kCalibrated);
         return v;
       },
       RoundAction::kNone,
       {},
       {},
       "every member holds a calibration"},
      {"the lowest id joins a calibrated site: it waits for the site's runner",
       [] {
         RoundView v = Fresh(0, {0, 1, 2});
         SetState(&v, 1, kCalibrated);
         SetState(&v, 2, kCalibrated);
         v.first_seen_calibrated_peer = kNow - seconds(2);
         return v;
       },
       RoundAction::kWait,
       {},
       {},
       "waiting join_wait"},
      {"... but not while the runner's join round sends it steps (longer than join_wait)",
       [] {
         RoundView v = Fresh(0, {0, 1, 2});
         SetState(&v, 1, kCalibrated);
         SetState(&v, 2, kCalibrated);
         v.first_seen_calibrated_peer = kNow - seconds(20);
         v.last_step_from_other = kNow - seconds(2);
         return v;
       },
       RoundAction::kWait,
       {},
       {},
       "another unit's round is calibrating this unit"},
      {"... and runs a round itself when no join round came",
       [] {
         RoundView v = Fresh(0, {0, 1, 2});
         SetState(&v, 1, kCalibrated);
         SetState(&v, 2, kCalibrated);
         v.first_seen_calibrated_peer = kNow - seconds(20);
         return v;
       },
       RoundAction::kRound,
       {0, 1, 2},
       {0, 1, 2},
       "did not calibrate this unit"},
  };
  for (const Row& row : rows) {
    SCOPED_TRACE(row.name);
    const RoundDecision d = DecideRound(row.view(), options);
    EXPECT_EQ(d.action, row.action) << RoundActionName(d.action) << ": " << d.why;
    EXPECT_NE(d.why.find(row.why), std::string::npos) << d.why;
    if (row.action == RoundAction::kRound || row.action == RoundAction::kJoinRound) {
      EXPECT_EQ(d.members, row.members);
      EXPECT_EQ(d.projecting, row.projecting);
    }
  }
  // An expected site size: wait for it, at most expect_wait from the start.
  RoundView early = Fresh(1, {1, 2, 3});
  early.started = kNow - seconds(10);
  EXPECT_EQ(DecideRound(early, expecting).action, RoundAction::kWait);
  EXPECT_NE(DecideRound(early, expecting).why.find("3 of 4 expected"), std::string::npos);
  RoundView late = early;
  late.started = kNow - seconds(200);
  EXPECT_EQ(DecideRound(late, expecting).action, RoundAction::kRound);
  RoundView full = Fresh(1, {1, 2, 3, 4});
  full.started = kNow - seconds(10);
  EXPECT_EQ(DecideRound(full, expecting).action, RoundAction::kRound);
}

RecalibrationAsk AskSite() { return {7, true, kInvalidNodeId}; }
RecalibrationAsk AskUnit(NodeId unit) { return {7, false, unit}; }

// An operator's ask to calibrate again: who carries it out, and how.
TEST(RoundPolicyTest, OperatorAsks) {
  struct AskRow {
    Row row;
    bool ask_done;
  };
  const std::vector<AskRow> rows = {
      {{"the site's runner, asked for the site: every member again",
        [] {
          RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3});
          v.asked = AskSite();
          return v;
        },
        RoundAction::kRound,
        {1, 2, 3},
        {1, 2, 3},
        "the operator asked to recalibrate the site"},
       true},
      {{"the site's runner, asked for one unit: a join round for it, the others held",
        [] {
          RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3});
          v.asked = AskUnit(2);
          return v;
        },
        RoundAction::kJoinRound,
        {1, 2, 3},
        {2},
        "against the 2 other units"},
       true},
      {{"... itself included",
        [] {
          RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3});
          v.asked = AskUnit(1);
          return v;
        },
        RoundAction::kJoinRound,
        {1, 2, 3},
        {1},
        "recalibrate unit 1"},
       true},
      {{"one unit of a two-unit site: one other unit is too few to hold, every member again",
        [] {
          RoundView v = SiteRunner(1, {1, 2}, {1, 2});
          v.asked = AskUnit(2);
          return v;
        },
        RoundAction::kRound,
        {1, 2},
        {1, 2},
        "calibrating every member"},
       true},
      {{"the lowest id without the site's solution, asked for one unit: every member again",
        [] {
          RoundView v = Fresh(1, {1, 2, 3});
          v.asked = AskUnit(3);
          return v;
        },
        RoundAction::kRound,
        {1, 2, 3},
        {1, 2, 3},
        "no site with two other units"},
       true},
      {{"an ask overrides saved calibrations that held their check",
        [] {
          RoundView v = Fresh(1, {1, 2});
          SetState(&v, 1, kVerified);
          SetState(&v, 2, kVerified);
          v.asked = AskSite();
          return v;
        },
        RoundAction::kRound,
        {1, 2},
        {1, 2},
        "recalibrate the site"},
       true},
      {{"not the runner: not its ask",
        [] {
          RoundView v = Fresh(2, {1, 2, 3});
          v.asked = AskSite();
          return v;
        },
        RoundAction::kNone,
        {},
        {},
        "unit 1 runs the rounds"},
       true},
      {{"the lowest id calibrated by a runner still present: that runner carries it out",
        [] {
          RoundView v = Fresh(1, {1, 2, 3});
          v.calibrated = true;
          v.calibrated_by = 2;
          v.asked = AskSite();
          return v;
        },
        RoundAction::kNone,
        {},
        {},
        "calibrated by unit 2, which carries out"},
       true},
      {{"the lowest id, not placed itself while others are: their runner carries it out",
        [] {
          RoundView v = Fresh(1, {1, 2, 3});
          SetState(&v, 2, kCalibrated);
          SetState(&v, 3, kCalibrated);
          v.asked = AskSite();
          return v;
        },
        RoundAction::kNone,
        {},
        {},
        "their runner carries out the operator's recalibration of the site"},
       true},
      {{"a unit that is not a member (or has no camera)",
        [] {
          RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3});
          v.asked = AskUnit(9);
          return v;
        },
        RoundAction::kNone,
        {},
        {},
        "not a member with a projector and a camera"},
       true},
      {{"its own round still runs: the ask waits for it",
        [] {
          RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3});
          v.round_running = true;
          v.asked = AskSite();
          return v;
        },
        RoundAction::kWait,
        {},
        {},
        "its round is running"},
       false},
      {{"a member not linked: the ask waits",
        [] {
          RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3});
          v.members[2].linked = false;
          v.asked = AskSite();
          return v;
        },
        RoundAction::kWait,
        {},
        {},
        "unit 3 is not linked"},
       false},
      {{"the member list settling: the ask waits",
        [] {
          RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3});
          v.member_list_age = milliseconds(100);
          v.asked = AskSite();
          return v;
        },
        RoundAction::kWait,
        {},
        {},
        "changed less than settle ago"},
       false},
  };
  for (const AskRow& ask_row : rows) {
    const Row& row = ask_row.row;
    SCOPED_TRACE(row.name);
    const RoundDecision d = DecideRound(row.view(), RoundPolicyOptions{});
    EXPECT_EQ(d.action, row.action) << RoundActionName(d.action) << ": " << d.why;
    EXPECT_NE(d.why.find(row.why), std::string::npos) << d.why;
    EXPECT_EQ(d.ask_done, ask_row.ask_done);
    if (row.action == RoundAction::kRound || row.action == RoundAction::kJoinRound) {
      EXPECT_EQ(d.members, row.members);
      EXPECT_EQ(d.projecting, row.projecting);
    }
  }
  // Without an ask, the same site's runner does nothing, and nothing is answered.
  const RoundDecision idle = DecideRound(SiteRunner(1, {1, 2, 3}, {1, 2, 3}), {});
  EXPECT_EQ(idle.action, RoundAction::kNone);
  EXPECT_FALSE(idle.ask_done);
}

// The site's runner after a round that placed units 1 and 2 and left unit 3 without a
// calibration, `failed` rounds in a row, the last one ended `ago`.
RoundView AfterFailedRound(int failed, RoundClock::duration ago) {
  RoundView v = SiteRunner(1, {1, 2, 3}, {1, 2, 3});
  SetState(&v, 3, kNone);
  v.site_units = 2;
  v.site_unit_ids = {1, 2};
  v.failed_rounds = failed;
  v.last_round_ended = kNow - ago;
  return v;
}

// A round that left units without a calibration is tried again, waiting longer each time.
TEST(RoundPolicyTest, FailedRoundsAreTriedAgainWithAGrowingWait) {
  const std::vector<Row> rows = {
      {"one failed round, 5 s ago: wait retry_wait (30 s)",
       [] { return AfterFailedRound(1, seconds(5)); },
       RoundAction::kWait,
       {},
       {},
       "the last round left unit 3 without a calibration; trying again 30 s after it"},
      {"... 31 s ago: a join round for the unit it left out",
       [] { return AfterFailedRound(1, seconds(31)); },
       RoundAction::kJoinRound,
       {1, 2, 3},
       {3},
       "trying again (1 of 3) for unit 3"},
      {"two in a row, 45 s ago: the wait doubled (60 s)",
       [] { return AfterFailedRound(2, seconds(45)); },
       RoundAction::kWait,
       {},
       {},
       "trying again 60 s after it"},
      {"three in a row, 121 s ago: the third try",
       [] { return AfterFailedRound(3, seconds(121)); },
       RoundAction::kJoinRound,
       {1, 2, 3},
       {3},
       "trying again (3 of 3)"},
      {"four in a row: it gives up and says so",
       [] { return AfterFailedRound(4, seconds(1000)); },
       RoundAction::kNone,
       {},
       {},
       "4 rounds in a row left unit 3 without a calibration; not trying again"},
      {"a round whose solve failed: every member again",
       [] {
         RoundView v = Fresh(1, {1, 2});
         v.ran_round = true;
         v.last_round_members = {1, 2};
         v.failed_rounds = 1;
         v.last_round_ended = kNow - seconds(40);
         return v;
       },
       RoundAction::kRound,
       {1, 2},
       {1, 2},
       "the last round solved no site; calibrating all again"},
      {"a unit that failed and left is not waited for",
       [] {
         RoundView v = AfterFailedRound(1, seconds(31));
         v.members.pop_back();
         return v;
       },
       RoundAction::kNone,
       {},
       {},
       "every member was in the last round"},
  };
  for (const Row& row : rows) {
    SCOPED_TRACE(row.name);
    const RoundDecision d = DecideRound(row.view(), RoundPolicyOptions{});
    EXPECT_EQ(d.action, row.action) << RoundActionName(d.action) << ": " << d.why;
    EXPECT_NE(d.why.find(row.why), std::string::npos) << d.why;
    if (row.action == RoundAction::kRound || row.action == RoundAction::kJoinRound) {
      EXPECT_EQ(d.members, row.members);
      EXPECT_EQ(d.projecting, row.projecting);
    }
  }
  // A round that placed every unit it was to: nothing to try again.
  RoundView placed = AfterFailedRound(0, seconds(1000));
  SetState(&placed, 3, kCalibrated);
  EXPECT_EQ(DecideRound(placed, {}).action, RoundAction::kNone);
}

TEST(RoundPolicyTest, ReportsWhatItSawForTheNextAsk) {
  RoundView v = Fresh(0, {0, 1, 2});
  SetState(&v, 1, kCalibrated);
  const RoundDecision d = DecideRound(v, {});
  EXPECT_TRUE(d.saw_calibrated_peer);
  EXPECT_TRUE(d.saw_uncalibrated_member);
  // Without a first sighting yet, the wait counts from now.
  EXPECT_EQ(d.action, RoundAction::kWait);
  SetState(&v, 0, kCalibrated);
  SetState(&v, 2, kCalibrated);
  EXPECT_FALSE(DecideRound(v, {}).saw_uncalibrated_member);
}

TEST(RoundPolicyTest, OptionsCheck) {
  EXPECT_TRUE(RoundPolicyOptions{}.Check().ok());
  RoundPolicyOptions bad;
  bad.join_wait = -std::chrono::seconds(1);
  EXPECT_EQ(bad.Check().code(), StatusCode::kInvalidArgument);
  bad = RoundPolicyOptions{};
  bad.expected_units = -1;
  EXPECT_EQ(bad.Check().code(), StatusCode::kInvalidArgument);
  bad = RoundPolicyOptions{};
  bad.max_retries = -1;
  EXPECT_EQ(bad.Check().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace sandtable::node
