#include "net/event_publisher.h"

#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "tests/net/test_wait.h"

namespace sandtable::net {
namespace {

using std::chrono::milliseconds;
using testing::ReceiveWithin;
using testing::WaitFor;
// Generous: a loaded 2-core CI machine; the messages normally arrive in well under 1 ms.
constexpr milliseconds kDeadline{5000};

struct Site {
  zmq::context_t context;
  proto::MessageCounters counters, subscriber_counters;
  std::unique_ptr<EventPublisher> publisher;
};

std::unique_ptr<Site> MakeSite(EventPublisherLimits limits = {}) {
  auto site = std::make_unique<Site>();
  Expected<std::unique_ptr<EventPublisher>> publisher = EventPublisher::Bind(
      &site->context, SocketOptions{}, limits, "tcp://127.0.0.1:*", 0, 1, &site->counters, {});
  EXPECT_TRUE(publisher.ok()) << publisher.status().ToString();
  if (publisher.ok()) site->publisher = std::move(*publisher);
  return site;
}

std::unique_ptr<Channel> Subscribe(Site* site, uint32_t id) {
  auto socket = Socket::Create(&site->context, SocketType::kEventSubscriber);
  EXPECT_TRUE(socket.ok());
  EXPECT_TRUE((*socket)->Connect(site->publisher->endpoint()).ok());
  return std::make_unique<Channel>(std::move(*socket), id, 1, &site->subscriber_counters);
}

// Drains until the publisher has `n` subscribers. A subscriber's socket sends its subscription
// once it handles its connection, which libzmq does when the socket is used: the subscribers
// are polled meanwhile, as a node polls its own.
bool DrainUntil(Site* site, size_t n, const std::vector<Channel*>& subscribers) {
  return WaitFor(
      [&] {
        for (Channel* subscriber : subscribers) (void)subscriber->TryReceive();
        EXPECT_TRUE(site->publisher->Drain().ok());
        return site->publisher->subscribers() == n;
      },
      kDeadline);
}

wire::Envelope Event(uint64_t version) {
  wire::Envelope e;
  e.mutable_member_list()->set_version(version);
  return e;
}

TEST(EventPublisherTest, EverySubscriberGetsEachEventWithOneSequence) {
  std::unique_ptr<Site> site = MakeSite();
  std::unique_ptr<Channel> a = Subscribe(site.get(), 1);
  std::unique_ptr<Channel> b = Subscribe(site.get(), 2);
  ASSERT_TRUE(DrainUntil(site.get(), 2, {a.get(), b.get()}));
  for (uint64_t version = 1; version <= 3; ++version) {
    ASSERT_TRUE(site->publisher->Publish(Event(version)).ok());
    std::optional<Incoming> got_a = ReceiveWithin(a.get(), kDeadline);
    std::optional<Incoming> got_b = ReceiveWithin(b.get(), kDeadline);
    ASSERT_TRUE(got_a && got_b);
    EXPECT_EQ(got_a->envelope.member_list().version(), version);
    EXPECT_EQ(got_b->envelope.member_list().version(), version);
    EXPECT_EQ(got_a->envelope.sequence(), got_b->envelope.sequence());
  }
  EXPECT_EQ(site->publisher->stats().registered, 2u);
  EXPECT_EQ(site->subscriber_counters.total_rejected(), 0u) << "a gap or a bad message";
}

TEST(EventPublisherTest, AnythingButASubscriptionIsDroppedAndCounted) {
  std::unique_ptr<Site> site = MakeSite();
  auto dealer = Socket::Create(&site->context, SocketType::kDealer);
  ASSERT_TRUE(dealer.ok());
  ASSERT_TRUE((*dealer)->Connect(site->publisher->endpoint()).ok());
  ASSERT_TRUE((*dealer)->Send({std::string("\x01topic", 6)}).ok());
  ASSERT_TRUE(WaitFor(
      [&] {
        EXPECT_TRUE(site->publisher->Drain().ok());
        return site->publisher->stats().refused == 1;
      },
      kDeadline));
  EXPECT_EQ(site->publisher->subscribers(), 0u);
  EXPECT_EQ(site->counters.rejected(proto::RejectReason::kWrongType), 1u);
}

TEST(EventPublisherTest, SubscribersPastTheLimitAreRefused) {
  EventPublisherLimits limits;
  limits.max_subscribers = 2;
  std::unique_ptr<Site> site = MakeSite(limits);
  std::vector<std::unique_ptr<Channel>> subscribers;
  for (uint32_t id = 1; id <= 3; ++id) subscribers.push_back(Subscribe(site.get(), id));
  ASSERT_TRUE(WaitFor(
      [&] {
        for (auto& subscriber : subscribers) (void)subscriber->TryReceive();
        EXPECT_TRUE(site->publisher->Drain().ok());
        return site->publisher->stats().refused_full == 1;
      },
      kDeadline));
  EXPECT_EQ(site->publisher->subscribers(), 2u);
}

TEST(EventPublisherTest, AGoneSubscriberIsForgottenAndItsNextConnectionRegisters) {
  std::unique_ptr<Site> site = MakeSite();
  std::unique_ptr<Channel> stays = Subscribe(site.get(), 1);
  std::unique_ptr<Channel> leaves = Subscribe(site.get(), 2);
  ASSERT_TRUE(DrainUntil(site.get(), 2, {stays.get(), leaves.get()}));
  leaves.reset();
  ASSERT_TRUE(WaitFor(
      [&] {
        EXPECT_TRUE(site->publisher->Publish(Event(1)).ok());
        return site->publisher->stats().forgotten == 1;
      },
      kDeadline));
  EXPECT_EQ(site->publisher->subscribers(), 1u);
  std::unique_ptr<Channel> again = Subscribe(site.get(), 2);
  ASSERT_TRUE(DrainUntil(site.get(), 2, {stays.get(), again.get()}));
  ASSERT_TRUE(site->publisher->Publish(Event(7)).ok());
  std::optional<Incoming> got = ReceiveWithin(again.get(), kDeadline);
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->envelope.member_list().version(), 7u);
}

// The publisher's program restarts on the same endpoint: the subscriber's new connection
// subscribes again by itself.
TEST(EventPublisherTest, ASubscriberSubscribesAgainToARestartedPublisher) {
  std::unique_ptr<Site> site = MakeSite();
  std::unique_ptr<Channel> subscriber = Subscribe(site.get(), 1);
  ASSERT_TRUE(DrainUntil(site.get(), 1, {subscriber.get()}));
  const std::string endpoint = site->publisher->endpoint();
  site->publisher.reset();
  // libzmq closes the old listener on its I/O thread: the port may be busy for a moment.
  ASSERT_TRUE(WaitFor(
      [&] {
        Expected<std::unique_ptr<EventPublisher>> again =
            EventPublisher::Bind(&site->context, SocketOptions{}, EventPublisherLimits{}, endpoint,
                                 0, 2, &site->counters, {});
        if (again.ok()) site->publisher = std::move(*again);
        return again.ok();
      },
      kDeadline));
  ASSERT_TRUE(DrainUntil(site.get(), 1, {subscriber.get()})) << "no subscription again";
  ASSERT_TRUE(site->publisher->Publish(Event(9)).ok());
  std::optional<Incoming> got = ReceiveWithin(subscriber.get(), kDeadline);
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->envelope.member_list().version(), 9u);
}

TEST(EventPublisherTest, LimitsAreChecked) {
  EventPublisherLimits limits;
  limits.max_message_bytes = 100;
  EXPECT_FALSE(limits.Check().ok());
  limits = {};
  limits.max_subscribers = 0;
  EXPECT_FALSE(limits.Check().ok());
  EXPECT_TRUE(EventPublisherLimits{}.Check().ok());
}

}  // namespace
}  // namespace sandtable::net
