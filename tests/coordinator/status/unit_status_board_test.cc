// UnitStatusBoard: a member's own status kept, others refused, the console's states (discovered,
// calibrating, blending, stalled, lost, forgotten).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "coordinator/status/unit_status_board.h"

namespace sandtable::coordinator {
namespace {

using namespace std::chrono_literals;

struct Site {
  MembershipTable members{MembershipOptions{}};
  UnitStatusBoard board;
  Clock::time_point t0 = Clock::now();

  void Join(NodeId id, const std::string& connection) {
    wire::Hello hello;
    hello.set_incarnation(1);
    hello.mutable_endpoints()->set_peer_router("tcp://127.0.0.1:4000" + std::to_string(id));
    ASSERT_EQ(members.OnHello(id, hello, connection, t0, [](const std::string&) { return true; }),
              HelloOutcome::kJoined);
  }
};

wire::UnitStatus Calibrated(bool blended) {
  wire::UnitStatus s;
  s.set_calibration_state(wire::CALIBRATION_STATE_CALIBRATED);
  s.set_phase("calibrated");
  s.set_host_name("unit-a");
  for (const auto& [x, y] : {std::pair{0.0, 0.0}, {1.0, 0.0}, {1.0, 0.5}, {0.0, 0.5}}) {
    wire::Vector2* p = s.add_footprint_m();
    p->set_x(x);
    p->set_y(y);
  }
  s.set_predicted_rms_mm(0.4);
  s.set_blended(blended);
  s.set_pattern("grid");
  return s;
}

TEST(UnitStatusBoardTest, KeepsAMembersOwnStatusAndSaysItsState) {
  Site site;
  site.Join(3, "conn-3");
  site.board.Sweep(site.members, site.t0);
  EXPECT_EQ(site.board.ConsoleState(3, site.members, site.t0), "discovered");
  wire::UnitStatus calibrating;
  calibrating.set_calibration_state(wire::CALIBRATION_STATE_NONE);
  calibrating.set_phase("calibrating");
  ASSERT_TRUE(site.board.Update(3, "conn-3", calibrating, site.members, site.t0).ok());
  EXPECT_EQ(site.board.ConsoleState(3, site.members, site.t0), "calibrating");
  ASSERT_TRUE(site.board.Update(3, "conn-3", Calibrated(false), site.members, site.t0).ok());
  EXPECT_EQ(site.board.ConsoleState(3, site.members, site.t0), "calibrated");
  ASSERT_TRUE(site.board.Update(3, "conn-3", Calibrated(true), site.members, site.t0).ok());
  EXPECT_EQ(site.board.ConsoleState(3, site.members, site.t0), "blending");

  site.members.CountReceived(3, "conn-3", 120);
  const nlohmann::json units = site.board.Json(site.members, site.t0 + 50ms);
  ASSERT_EQ(units.size(), 1u);
  EXPECT_EQ(units[0]["link"], nlohmann::json({{"messages_in", 1}, {"bytes_in", 120}}));
  EXPECT_EQ(units[0]["node_id"], 3);
  EXPECT_EQ(units[0]["state"], "blending");
  EXPECT_EQ(units[0]["host_name"], "unit-a");
  EXPECT_EQ(units[0]["pattern"], "grid");
  ASSERT_EQ(units[0]["footprint_m"].size(), 4u);
  EXPECT_EQ(units[0]["footprint_m"][2], nlohmann::json({1.0, 0.5}));
  EXPECT_DOUBLE_EQ(units[0]["predicted_rms_mm"].get<double>(), 0.4);
  EXPECT_NEAR(units[0]["heartbeat_age_s"].get<double>(), 0.05, 1e-9);

  // Calibrated, and calibrated again by a round now: calibrating until the round's result.
  wire::UnitStatus again = Calibrated(true);
  again.set_phase("calibrating");
  ASSERT_TRUE(site.board.Update(3, "conn-3", again, site.members, site.t0).ok());
  EXPECT_EQ(site.board.ConsoleState(3, site.members, site.t0), "calibrating");

  wire::UnitStatus failed;
  failed.set_calibration_state(wire::CALIBRATION_STATE_NONE);
  failed.set_phase("failed");
  failed.set_last_error("calibration failed: no plane");
  ASSERT_TRUE(site.board.Update(3, "conn-3", failed, site.members, site.t0).ok());
  EXPECT_EQ(site.board.ConsoleState(3, site.members, site.t0), "failed");
  wire::UnitStatus stuck;  // a unit without self-calibration says why it cannot work
  stuck.set_phase("no factory calibration");
  stuck.set_last_error("no factory calibration (--factory): ...");
  ASSERT_TRUE(site.board.Update(3, "conn-3", stuck, site.members, site.t0).ok());
  EXPECT_EQ(site.board.ConsoleState(3, site.members, site.t0), "failed");
}

TEST(UnitStatusBoardTest, RefusesAnotherConnectionsClaimAndStatusOverTheLimits) {
  Site site;
  site.Join(3, "conn-3");
  EXPECT_EQ(site.board.Update(3, "conn-4", Calibrated(true), site.members, site.t0).code(),
            StatusCode::kPermissionDenied);
  EXPECT_EQ(site.board.Update(9, "conn-3", Calibrated(true), site.members, site.t0).code(),
            StatusCode::kPermissionDenied);
  wire::UnitStatus huge = Calibrated(true);
  for (int i = 0; i < kMaxFootprintPoints; ++i) huge.add_footprint_m();
  EXPECT_EQ(site.board.Update(3, "conn-3", huge, site.members, site.t0).code(),
            StatusCode::kInvalidArgument);
  wire::UnitStatus nan = Calibrated(true);
  nan.mutable_footprint_m(0)->set_x(std::nan(""));
  EXPECT_EQ(site.board.Update(3, "conn-3", nan, site.members, site.t0).code(),
            StatusCode::kInvalidArgument);
  wire::UnitStatus wordy = Calibrated(true);
  wordy.set_last_error(std::string(kMaxStatusTextChars + 1, 'x'));
  EXPECT_EQ(site.board.Update(3, "conn-3", wordy, site.members, site.t0).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(site.board.refused(), 5u);
  EXPECT_EQ(site.board.size(), 0u);  // nothing kept: the member is still only discovered
  EXPECT_EQ(site.board.ConsoleState(3, site.members, site.t0), "discovered");
}

TEST(UnitStatusBoardTest, SilentMembersStallAndGoneMembersAreLostThenForgotten) {
  Site site;
  site.Join(3, "conn-3");
  site.Join(4, "conn-4");
  ASSERT_TRUE(site.board.Update(3, "conn-3", Calibrated(true), site.members, site.t0).ok());
  ASSERT_TRUE(site.board.Update(4, "conn-4", Calibrated(true), site.members, site.t0).ok());
  const auto period = site.members.options().heartbeat_period;
  const Clock::time_point silent = site.t0 + kStalledAfterPeriods * period + 1ms;
  EXPECT_EQ(site.board.ConsoleState(3, site.members, silent), "stalled");
  // Unit 4 says goodbye: lost, with its last status kept for the operator.
  ASSERT_EQ(site.members.OnGoodbye(4, 1, "conn-4"), GoodbyeOutcome::kLeft);
  const Clock::time_point gone = site.t0 + 10ms;
  site.board.Sweep(site.members, gone);
  EXPECT_EQ(site.board.ConsoleState(4, site.members, gone), "lost");
  nlohmann::json units = site.board.Json(site.members, gone + 1s);
  ASSERT_EQ(units.size(), 2u);
  EXPECT_EQ(units[1]["state"], "lost");
  EXPECT_NEAR(units[1]["since_s"].get<double>(), 1.0, 1e-6);
  EXPECT_TRUE(units[1]["heartbeat_age_s"].is_null());
  EXPECT_TRUE(units[1]["link"].is_null());
  EXPECT_EQ(units[1]["footprint_m"].size(), 4u);
  site.board.Sweep(site.members, gone + kLostKeptFor + 1s);
  EXPECT_EQ(site.board.size(), 1u);
  EXPECT_EQ(site.board.ConsoleState(4, site.members, gone + kLostKeptFor + 1s), "");
}

}  // namespace
}  // namespace sandtable::coordinator
