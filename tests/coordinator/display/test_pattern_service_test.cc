// The operators' test patterns through a real coordinator: requests on its ROUTER, the state on
// its PUB (docs/render.md).
#include "coordinator/display/test_pattern_service.h"

#include <atomic>
#include <thread>

#include <gtest/gtest.h>

#include "net/channel.h"
#include "tests/coordinator/testing/service_fixture.h"
#include "tests/net/test_wait.h"

namespace sandtable::coordinator {
namespace {

using namespace std::chrono_literals;
constexpr auto kDeadline = 5s;

class TestPatternServiceTest : public testing::ServiceFixture {
 protected:
  void SetUp() override { StartWith(&service_); }

  std::optional<wire::TestPatternReply> Request(bool all, uint32_t node, const std::string& p) {
    wire::Envelope request;
    request.mutable_test_pattern_request()->set_all_nodes(all);
    request.mutable_test_pattern_request()->set_node_id(node);
    request.mutable_test_pattern_request()->set_pattern(p);
    EXPECT_TRUE(dealer_->Send(std::move(request)).ok());
    auto in = net::testing::ReceiveWithin(dealer_.get(), kDeadline);
    if (!in || !in->envelope.has_test_pattern_reply()) return std::nullopt;
    return in->envelope.test_pattern_reply();
  }

  // The next published state with at least `changes` changes.
  std::optional<wire::TestPatternState> StateWith(uint64_t changes) {
    const auto until = std::chrono::steady_clock::now() + kDeadline;
    while (std::chrono::steady_clock::now() < until) {
      auto in = net::testing::ReceiveWithin(sub_.get(), 100ms);
      if (in && in->envelope.has_test_pattern_state() &&
          in->envelope.test_pattern_state().change_count() >= changes) {
        return in->envelope.test_pattern_state();
      }
    }
    return std::nullopt;
  }

  TestPatternService service_{200ms};
};

TEST_F(TestPatternServiceTest, SiteAndNodePatternsArePublished) {
  // Republished while nothing changes: a late subscriber learns the site shows the show.
  std::optional<wire::TestPatternState> first = StateWith(0);
  ASSERT_TRUE(first.has_value());
  EXPECT_EQ(first->site_pattern(), "none");

  std::optional<wire::TestPatternReply> reply = Request(true, 0, "grid");
  ASSERT_TRUE(reply.has_value());
  EXPECT_TRUE(reply->accepted()) << reply->reason();
  std::optional<wire::TestPatternState> state = StateWith(1);
  ASSERT_TRUE(state.has_value());
  EXPECT_EQ(state->site_pattern(), "grid");

  reply = Request(false, 3, "id");
  ASSERT_TRUE(reply && reply->accepted());
  state = StateWith(2);
  ASSERT_TRUE(state.has_value());
  EXPECT_EQ(state->site_pattern(), "grid");
  ASSERT_EQ(state->node_patterns().count(3), 1u);
  EXPECT_EQ(state->node_patterns().at(3), "id");

  // "" clears the node's own; a site-wide request clears every node's.
  reply = Request(false, 3, "");
  ASSERT_TRUE(reply && reply->accepted());
  state = StateWith(3);
  ASSERT_TRUE(state.has_value());
  EXPECT_EQ(state->node_patterns().count(3), 0u);
  ASSERT_TRUE(Request(false, 4, "bars")->accepted());
  ASSERT_TRUE(Request(true, 0, "white")->accepted());
  state = StateWith(5);
  ASSERT_TRUE(state.has_value());
  EXPECT_EQ(state->site_pattern(), "white");
  EXPECT_TRUE(state->node_patterns().empty());
}

TEST_F(TestPatternServiceTest, UnknownPatternsAndReservedIdsAreRefusedByName) {
  std::optional<wire::TestPatternReply> reply = Request(true, 0, "checkerboard");
  ASSERT_TRUE(reply.has_value());
  EXPECT_FALSE(reply->accepted());
  EXPECT_NE(reply->reason().find("checkerboard"), std::string::npos) << reply->reason();
  reply = Request(false, kCoordinatorSenderId, "grid");
  ASSERT_TRUE(reply.has_value());
  EXPECT_FALSE(reply->accepted());
  EXPECT_NE(reply->reason().find("reserved"), std::string::npos) << reply->reason();
  EXPECT_EQ(service_.state().change_count(), 0u);
  EXPECT_EQ(service_.state().site_pattern(), "none");
}

}  // namespace
}  // namespace sandtable::coordinator
