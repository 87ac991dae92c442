// SequenceTracker is bounded: idle senders expire, and a flood of fake sender ids never holds
// more than max_senders entries (the 60 bytes per sender ever seen no longer accumulate).
#include "proto/sequence_tracker.h"

#include <gtest/gtest.h>

#include "proto/envelope_stamper.h"

namespace sandtable::proto {
namespace {

using Clock = SequenceTracker::Clock;
using std::chrono::milliseconds;

wire::Envelope Heartbeat(uint32_t sender, uint64_t incarnation, uint64_t sequence) {
  wire::Envelope e;
  e.set_protocol_version(kProtocolVersion);
  e.set_sender_id(sender);
  e.set_sender_incarnation(incarnation);
  e.set_sequence(sequence);
  e.mutable_heartbeat()->set_incarnation(incarnation);
  return e;
}

TEST(SequenceTrackerBoundTest, FloodOfSenderIdsKeepsAtMostMaxSenders) {
  constexpr size_t kMaxSenders = 64;
  constexpr uint32_t kFakeSenders = 100000;
  SequenceTracker tracker({kMaxSenders, milliseconds(60000)});
  const Clock::time_point t0 = Clock::now();
  for (uint32_t id = 1; id <= kFakeSenders; ++id) {
    ASSERT_TRUE(tracker.Accept(Heartbeat(id, 1, 1), nullptr, t0).ok());
    ASSERT_LE(tracker.size(), kMaxSenders);
  }
  EXPECT_EQ(tracker.size(), kMaxSenders);
  EXPECT_EQ(tracker.expired(), kFakeSenders - kMaxSenders);
  // The most recently heard are still tracked: a replay from one of them is still refused.
  MessageCounters counters;
  EXPECT_FALSE(tracker.Accept(Heartbeat(kFakeSenders, 1, 1), &counters, t0).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kOutOfOrder), 1u);
}

TEST(SequenceTrackerBoundTest, IdleSendersExpireActiveOnesStay) {
  constexpr milliseconds kExpiry{1000};
  SequenceTracker tracker({4096, kExpiry});
  const Clock::time_point t0 = Clock::now();
  ASSERT_TRUE(tracker.Accept(Heartbeat(1, 7, 1), nullptr, t0).ok());  // goes silent
  ASSERT_TRUE(tracker.Accept(Heartbeat(2, 7, 1), nullptr, t0).ok());  // keeps talking
  ASSERT_TRUE(tracker.Accept(Heartbeat(2, 7, 2), nullptr, t0 + kExpiry / 2).ok());
  ASSERT_TRUE(tracker.Accept(Heartbeat(2, 7, 3), nullptr, t0 + kExpiry + milliseconds(1)).ok());
  EXPECT_EQ(tracker.size(), 1u);  // sender 1 expired
  EXPECT_EQ(tracker.expired(), 1u);
  // Sender 2 still tracked: its old sequence is refused.
  EXPECT_FALSE(tracker.Accept(Heartbeat(2, 7, 3), nullptr, t0 + kExpiry + milliseconds(2)).ok());
  tracker.Forget(2);
  EXPECT_EQ(tracker.size(), 0u);
}

TEST(SequenceTrackerBoundTest, OptionsCheckRefusesNoRoomAndNoExpiry) {
  EXPECT_TRUE(SequenceTrackerOptions{}.Check().ok());
  EXPECT_FALSE((SequenceTrackerOptions{0, milliseconds(1000)}).Check().ok());
  EXPECT_FALSE((SequenceTrackerOptions{16, milliseconds(0)}).Check().ok());
  EXPECT_FALSE((SequenceTrackerOptions{16, milliseconds(-5)}).Check().ok());
}

// A forger on another connection claiming a sender's id and incarnation with high sequence
// numbers does not make the sender's own next message look out of order.
TEST(SequenceTrackerBoundTest, ConnectionsAreTrackedApart) {
  SequenceTracker tracker;
  const Clock::time_point t0 = Clock::now();
  ASSERT_TRUE(tracker.Accept(Heartbeat(7, 1, 1), nullptr, t0, "member").ok());
  ASSERT_TRUE(tracker.Accept(Heartbeat(7, 1, 1000000), nullptr, t0, "forger").ok());
  EXPECT_TRUE(tracker.Accept(Heartbeat(7, 1, 2), nullptr, t0, "member").ok());
  EXPECT_FALSE(tracker.Accept(Heartbeat(7, 1, 2), nullptr, t0, "member").ok());
  EXPECT_EQ(tracker.size(), 2u);
  tracker.Forget(7);  // on every connection
  EXPECT_EQ(tracker.size(), 0u);
}

}  // namespace
}  // namespace sandtable::proto
