// An operator's "calibrate again" through a real coordinator: requests on its ROUTER, the ask on
// its PUB (coordinator/calibration/recalibration_service.h).
#include "coordinator/calibration/recalibration_service.h"

#include <gtest/gtest.h>

#include "net/channel.h"
#include "tests/coordinator/testing/service_fixture.h"
#include "tests/net/test_wait.h"

namespace sandtable::coordinator {
namespace {

using namespace std::chrono_literals;
constexpr auto kDeadline = 5s;
constexpr NodeId kMember = 902;  // the fixture's DEALER, which says Hello as a node

class RecalibrationServiceTest : public testing::ServiceFixture {
 protected:
  void SetUp() override { StartWith(&service_); }

  void JoinAsMember() {
    wire::Envelope hello;
    hello.mutable_hello()->set_role(wire::ROLE_NODE);
    hello.mutable_hello()->set_incarnation(1);
    hello.mutable_hello()->mutable_endpoints()->set_peer_router("tcp://127.0.0.1:45017");
    ASSERT_TRUE(dealer_->Send(std::move(hello)).ok());
    auto in = net::testing::ReceiveWithin(dealer_.get(), kDeadline);
    ASSERT_TRUE(in && in->envelope.has_hello_ack());
    ASSERT_TRUE(in->envelope.hello_ack().accepted()) << in->envelope.hello_ack().reason();
  }

  std::optional<wire::RecalibrateReply> Request(bool all, uint32_t node) {
    wire::Envelope request;
    request.mutable_recalibrate_request()->set_all_units(all);
    request.mutable_recalibrate_request()->set_node_id(node);
    EXPECT_TRUE(dealer_->Send(std::move(request)).ok());
    const auto until = std::chrono::steady_clock::now() + kDeadline;
    while (std::chrono::steady_clock::now() < until) {
      auto in = net::testing::ReceiveWithin(dealer_.get(), 100ms);
      if (in && in->envelope.has_recalibrate_reply()) return in->envelope.recalibrate_reply();
    }
    return std::nullopt;
  }

  // The next published ask with at least `id`.
  std::optional<wire::RecalibrateAsk> AskWith(uint64_t id) {
    const auto until = std::chrono::steady_clock::now() + kDeadline;
    while (std::chrono::steady_clock::now() < until) {
      auto in = net::testing::ReceiveWithin(sub_.get(), 100ms);
      if (in && in->envelope.has_recalibrate_ask() &&
          in->envelope.recalibrate_ask().ask_id() >= id) {
        return in->envelope.recalibrate_ask();
      }
    }
    return std::nullopt;
  }

  RecalibrationService service_{200ms};
};

TEST_F(RecalibrationServiceTest, AcceptedAsksArePublishedWithGrowingIds) {
  // Published while nobody asked: a unit that starts learns the epoch and that none is open.
  std::optional<wire::RecalibrateAsk> first = AskWith(0);
  ASSERT_TRUE(first.has_value());
  EXPECT_EQ(first->ask_id(), 0u);
  EXPECT_NE(first->epoch(), 0u);

  JoinAsMember();
  std::optional<wire::RecalibrateReply> reply = Request(false, kMember);
  ASSERT_TRUE(reply.has_value());
  EXPECT_TRUE(reply->accepted()) << reply->reason();
  EXPECT_EQ(reply->ask_id(), 1u);
  std::optional<wire::RecalibrateAsk> ask = AskWith(1);
  ASSERT_TRUE(ask.has_value());
  EXPECT_FALSE(ask->all_units());
  EXPECT_EQ(ask->node_id(), kMember);
  EXPECT_EQ(ask->epoch(), first->epoch());

  reply = Request(true, 0);
  ASSERT_TRUE(reply && reply->accepted()) << (reply ? reply->reason() : "no reply");
  ask = AskWith(2);
  ASSERT_TRUE(ask.has_value());
  EXPECT_TRUE(ask->all_units());
  EXPECT_EQ(ask->ask_id(), 2u);
}

TEST_F(RecalibrationServiceTest, UnitsThatAreNotMembersAndEmptySitesAreRefused) {
  std::optional<wire::RecalibrateReply> reply = Request(true, 0);
  ASSERT_TRUE(reply.has_value());
  EXPECT_FALSE(reply->accepted());
  EXPECT_NE(reply->reason().find("no members"), std::string::npos) << reply->reason();

  JoinAsMember();
  reply = Request(false, 5);
  ASSERT_TRUE(reply.has_value());
  EXPECT_FALSE(reply->accepted());
  EXPECT_NE(reply->reason().find("unit 5 is not a member"), std::string::npos) << reply->reason();
  reply = Request(false, kCoordinatorSenderId);
  ASSERT_TRUE(reply.has_value());
  EXPECT_FALSE(reply->accepted());
  EXPECT_NE(reply->reason().find("reserved"), std::string::npos) << reply->reason();
  EXPECT_EQ(service_.ask().ask_id(), 0u);
}

}  // namespace
}  // namespace sandtable::coordinator
