// Catch-up paging between the real AnnotationService (coordinator) and the real
// EventStateService (node) over loopback TCP: a late joiner catches up whatever the size of the
// state - a snapshot larger than one page arrives in chunks, a long tail of events in pages -
// and ends with the coordinator's state; a request with more points than kMaxPointsPerRequest
// is refused with a reason naming the limit. One case holds 60 events of 100 000 points
// (72 MB of points, over the codec's 64 MiB message limit) with the default page size.
#include <gtest/gtest.h>

#include <functional>

#include "coordinator/annotations/annotation_service.h"
#include "net/channel.h"
#include "node/events/event_state_service.h"
#include "tests/cluster/annotation_test_util.h"
#include "tests/net/test_wait.h"

namespace sandtable::node {
namespace {

using cluster::testing::Begin;
using cluster::testing::End;
using cluster::testing::Points;
using std::chrono::milliseconds;

constexpr milliseconds kDeadline{60000};

Eigen::Vector3f PointOf(int stroke, int k) {
  return Eigen::Vector3f(1e-5f * static_cast<float>(k), 0.001f * static_cast<float>(stroke), 0.f);
}

class CatchUpPagingTest : public ::testing::Test {
 protected:
  void Start(coordinator::AnnotationServiceOptions options) {
    Expected<std::unique_ptr<coordinator::AnnotationStore>> store =
        coordinator::AnnotationStore::Open(":memory:");
    ASSERT_TRUE(store.ok());
    store_ = std::move(*store);
    service_ = std::make_unique<coordinator::AnnotationService>(store_.get(), options);
    coordinator::CoordinatorOptions o;
    o.membership.heartbeat_period = milliseconds(50);
    o.membership.misses_allowed = 1000;  // long steps of this test must not expire the node
    coordinator_ = std::make_unique<coordinator::CoordinatorServer>(o);
    coordinator_->AddService(service_.get());
    ASSERT_TRUE(coordinator_->Start().ok());
  }
  // Strokes of `points` points each, committed in events of `per_event` points.
  void Fill(int first_stroke, int strokes, int points, int per_event, bool end = true) {
    for (int s = first_stroke; s < first_stroke + strokes; ++s) {
      std::vector<wire::AnnotationEvent> batch{Begin(s)};
      for (int k = 0; k < points; k += per_event) {
        std::vector<Eigen::Vector3f> chunk;
        for (int i = k; i < std::min(points, k + per_event); ++i) chunk.push_back(PointOf(s, i));
        batch.push_back(Points(s, k, chunk));
      }
      if (end) batch.push_back(End(s, points));
      Expected<coordinator::CommitReport> report = store_->Commit(&batch);
      ASSERT_TRUE(report.ok());
      ASSERT_EQ(report->num_committed, batch.size());
    }
  }
  void StartNode() {
    NodeOptions o;
    o.id = 4;
    o.coordinator_requests = coordinator_->request_endpoint();
    o.coordinator_events = coordinator_->event_endpoint();
    o.heartbeat_period = milliseconds(50);
    node_ = std::make_unique<NodeRuntime>(o);
    node_->AddService(&events_);
    ASSERT_TRUE(node_->Start().ok());
  }
  bool StepUntil(const std::function<bool()>& done, milliseconds deadline = kDeadline) {
    const auto until = std::chrono::steady_clock::now() + deadline;
    while (std::chrono::steady_clock::now() < until) {
      if (!coordinator_->Step(milliseconds(1)).ok()) return false;
      if (node_ && !node_->Step(milliseconds(1)).ok()) return false;
      if (done()) return true;
    }
    return done();
  }
  bool SameState() const {
    return events_.annotations().ToSnapshot().SerializeAsString() ==
           store_->state().ToSnapshot().SerializeAsString();
  }

  std::unique_ptr<coordinator::AnnotationStore> store_;
  std::unique_ptr<coordinator::AnnotationService> service_;
  std::unique_ptr<coordinator::CoordinatorServer> coordinator_;
  EventStateService events_{milliseconds(200)};
  std::unique_ptr<NodeRuntime> node_;
};

TEST_F(CatchUpPagingTest, SnapshotLargerThanAPageArrivesInChunks) {
  coordinator::AnnotationServiceOptions options;
  options.catch_up_page_bytes = 64 << 10;  // 64 KiB: a 3.6 MB state takes ~55 chunks
  Start(options);
  Fill(1, 30, 10000, 10000);
  StartNode();
  ASSERT_TRUE(StepUntil([&] { return events_.annotations().last_sequence() == 90; }));
  EXPECT_TRUE(SameState());
  EXPECT_GT(service_->counters().snapshot_chunks_sent, 50u);
  EXPECT_EQ(events_.counters().snapshot_chunks, service_->counters().snapshot_chunks_sent);
  EXPECT_EQ(events_.counters().snapshots_refused, 0u);
  std::cout << "snapshot chunks " << service_->counters().snapshot_chunks_sent << ", catch-up "
            << "requests " << events_.counters().catch_ups_requested << "\n";
}

TEST_F(CatchUpPagingTest, LongTailOfEventsArrivesInPagesAndLiveEventsFollow) {
  coordinator::AnnotationServiceOptions options;
  options.catch_up_page_bytes = 64 << 10;
  Start(options);
  Fill(1, 1, 10, 10);
  StartNode();
  ASSERT_TRUE(StepUntil([&] { return events_.annotations().last_sequence() == 3; }));
  // The node misses 200 events of ~12 kB (2.4 MB, ~40 pages) published to nobody, then one
  // live event reveals the gap.
  Fill(2, 1, 200 * 1000, 1000, /*end=*/false);
  wire::AnnotationEvent live = End(2, 200 * 1000);
  service_->Submit(live);
  ASSERT_TRUE(StepUntil([&] { return events_.annotations().last_sequence() == 205; }));
  EXPECT_TRUE(SameState());
  EXPECT_EQ(service_->counters().snapshot_chunks_sent, 0u);
  EXPECT_GT(events_.counters().catch_ups_requested, 30u);
}

TEST_F(CatchUpPagingTest, ExpiredSnapshotStartsAgain) {
  coordinator::AnnotationServiceOptions options;
  options.catch_up_page_bytes = 64 << 10;
  options.snapshot_hold = milliseconds(0);  // dropped at every step
  options.max_catch_up_events = 1;          // every joiner needs a fresh snapshot
  Start(options);
  Fill(1, 5, 10000, 10000);
  StartNode();
  // Chunks of a snapshot dropped between requests are refused as expired; the node starts
  // again each time and (since snapshots are rebuilt for every fresh request) never ends in
  // a wrong state.
  StepUntil([&] { return service_->counters().snapshots_expired >= 3; }, milliseconds(10000));
  EXPECT_GE(service_->counters().snapshots_expired, 3u);
  EXPECT_EQ(events_.counters().snapshots_refused, 0u);
  EXPECT_TRUE(events_.annotations().last_sequence() == 0 || SameState());
}

TEST_F(CatchUpPagingTest, RequestOverThePointLimitIsRefusedWithTheLimitNamed) {
  Start(coordinator::AnnotationServiceOptions{});
  zmq::context_t context;
  proto::MessageCounters counters;
  Expected<std::unique_ptr<net::Socket>> dealer =
      net::Socket::Create(&context, net::SocketType::kDealer);
  ASSERT_TRUE(dealer.ok());
  ASSERT_TRUE((*dealer)->Connect(coordinator_->request_endpoint()).ok());
  net::Channel channel(std::move(*dealer), 7001, 1, &counters);
  auto request = [&](wire::AnnotationEvent e) -> wire::AnnotationAck {
    wire::Envelope envelope;
    *envelope.mutable_annotation_request() = std::move(e);
    EXPECT_TRUE(channel.Send(std::move(envelope)).ok());
    const auto until = std::chrono::steady_clock::now() + milliseconds(10000);
    while (std::chrono::steady_clock::now() < until) {
      EXPECT_TRUE(coordinator_->Step(milliseconds(1)).ok());
      std::optional<net::Incoming> in = net::testing::ReceiveWithin(&channel, milliseconds(1));
      if (in && in->envelope.has_annotation_ack()) return in->envelope.annotation_ack();
    }
    ADD_FAILURE() << "no ack";
    return {};
  };
  ASSERT_TRUE(request(Begin(1)).accepted());
  // 60 requests of 100 000 points (the 72 MB): each refused, nothing stored.
  std::vector<Eigen::Vector3f> many(100000, Eigen::Vector3f(0.1f, 0.2f, 0.f));
  for (int i = 0; i < 60; ++i) {
    const wire::AnnotationAck ack = request(Points(1, 0, many));
    ASSERT_FALSE(ack.accepted());
    ASSERT_NE(ack.reason().find("kMaxPointsPerRequest = 10000"), std::string::npos) << ack.reason();
  }
  EXPECT_EQ(service_->counters().requests_over_point_limit, 60u);
  EXPECT_EQ(store_->state().NumPoints(), 0u);
  // At the limit it is accepted.
  many.resize(coordinator::kMaxPointsPerRequest);
  EXPECT_TRUE(request(Points(1, 0, many)).accepted());
}

// The case with the default page size: 60 events of 100 000 points (committed
// through the store as an import would: 72 MB of points) are more than one 64 MiB message.
TEST_F(CatchUpPagingTest, StateOverTheCodecLimitReachesALateJoiner) {
  Start(coordinator::AnnotationServiceOptions{});
  Fill(1, 60, 100000, 100000);
  ASSERT_GT(store_->state().NumPoints() * 12, size_t{64} << 20);
  StartNode();
  ASSERT_TRUE(StepUntil([&] { return events_.annotations().last_sequence() == 180; }));
  EXPECT_TRUE(SameState());
  EXPECT_GE(service_->counters().snapshot_chunks_sent, 9u);  // 72 MB in chunks of 8 MiB
}

}  // namespace
}  // namespace sandtable::node
