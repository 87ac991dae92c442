// Through the real server: a DEALER sends Seek/Play/Rate, a SUB receives timeline_clock events.
#include "coordinator/timeline/timeline_service.h"

#include <atomic>
#include <thread>

#include <gtest/gtest.h>

#include "net/channel.h"
#include "tests/coordinator/testing/service_fixture.h"
#include "tests/net/test_wait.h"

namespace sandtable::coordinator {
namespace {

using namespace std::chrono_literals;
constexpr auto kDeadline = 5000ms;
constexpr double kTolerance_s = 1e-6;
constexpr double kTolerance_m = 1e-9;
constexpr double kSpeed_m_per_s = 0.1;

// Track 4 walks along x at 0.1 m/s for 100 s (one sample per second).
PersonnelTracks Walker() {
  std::string csv = "track_id,t_s,x_m,y_m,z_m\n";
  for (int k = 0; k <= 100; ++k) {
    csv += "4," + std::to_string(k) + "," + std::to_string(kSpeed_m_per_s * k) + ",0.5,0\n";
  }
  Expected<PersonnelTracks> t = PersonnelTracks::Parse(csv, "walker");
  EXPECT_TRUE(t.ok()) << t.status().ToString();
  return *t;
}

class TimelineServiceTest : public testing::ServiceFixture {
 protected:
  void SetUp() override { StartWith(&service_); }

  // Next clock event satisfying `pred` (others skipped), within the deadline.
  std::optional<wire::TimelineClock> NextClock(
      const std::function<bool(const wire::TimelineClock&)>& pred) {
    const auto until = std::chrono::steady_clock::now() + kDeadline;
    while (std::chrono::steady_clock::now() < until) {
      auto in = net::testing::ReceiveWithin(sub_.get(), 100ms);
      if (in && in->envelope.has_timeline_clock() && pred(in->envelope.timeline_clock())) {
        return in->envelope.timeline_clock();
      }
    }
    return std::nullopt;
  }

  std::optional<wire::TimelineReply> Request(wire::Envelope request) {
    EXPECT_TRUE(dealer_->Send(std::move(request)).ok());
    auto in = net::testing::ReceiveWithin(dealer_.get(), kDeadline);
    if (!in || !in->envelope.has_timeline_reply()) return std::nullopt;
    return in->envelope.timeline_reply();
  }

  TimelineService service_{Walker()};
};

TEST_F(TimelineServiceTest, SeekPlayRateDriveTheClockOnThePub) {
  // The periodic clock reaches a fresh subscriber: paused at 0.
  std::optional<wire::TimelineClock> first = NextClock([](const auto&) { return true; });
  ASSERT_TRUE(first.has_value());
  EXPECT_FALSE(first->playing());
  EXPECT_NEAR(first->duration_s(), 100.0, kTolerance_s);
  ASSERT_EQ(first->tracks_size(), 1);

  wire::Envelope seek;
  seek.mutable_seek()->set_position_s(10.0);
  std::optional<wire::TimelineReply> reply = Request(seek);
  ASSERT_TRUE(reply.has_value());
  EXPECT_TRUE(reply->accepted()) << reply->reason();
  EXPECT_NEAR(reply->clock().media_time_s(), 10.0, kTolerance_s);
  std::optional<wire::TimelineClock> c =
      NextClock([](const auto& k) { return k.change_count() >= 1; });
  ASSERT_TRUE(c.has_value());
  EXPECT_NEAR(c->media_time_s(), 10.0, kTolerance_s);
  EXPECT_NEAR(c->tracks(0).position_in_table_m().x(), 1.0, kTolerance_m);
  EXPECT_TRUE(c->tracks(0).active());

  wire::Envelope play;
  play.mutable_play();
  reply = Request(play);
  ASSERT_TRUE(reply.has_value());
  EXPECT_TRUE(reply->accepted());
  EXPECT_TRUE(reply->clock().playing());
  // Two successive playing clocks agree with extrapolation: media advances by rate * wall.
  std::optional<wire::TimelineClock> a = NextClock([](const auto& k) { return k.playing(); });
  std::optional<wire::TimelineClock> b = NextClock(
      [&](const auto& k) { return k.playing() && k.sample_time_ns() > a->sample_time_ns(); });
  ASSERT_TRUE(a.has_value() && b.has_value());
  EXPECT_GE(a->media_time_s(), 10.0);
  EXPECT_NEAR(b->media_time_s() - a->media_time_s(),
              1e-9 * static_cast<double>(b->sample_time_ns() - a->sample_time_ns()), kTolerance_s);
  // Track position follows media time (0.1 m/s along x).
  EXPECT_NEAR(b->tracks(0).position_in_table_m().x(), kSpeed_m_per_s * b->media_time_s(), 1e-6);

  wire::Envelope rate;
  rate.mutable_rate()->set_rate(8.0);
  reply = Request(rate);
  ASSERT_TRUE(reply.has_value() && reply->accepted());
  std::optional<wire::TimelineClock> r8 = NextClock([](const auto& k) { return k.rate() == 8.0; });
  ASSERT_TRUE(r8.has_value());

  // Reverse play is refused with a reason; the clock keeps its rate.
  rate.mutable_rate()->set_rate(-1.0);
  reply = Request(rate);
  ASSERT_TRUE(reply.has_value());
  EXPECT_FALSE(reply->accepted());
  EXPECT_NE(reply->reason().find("reverse"), std::string::npos) << reply->reason();
  EXPECT_EQ(reply->clock().rate(), 8.0);

  // Seek past the end clamps; playing there reaches the end and the clock pauses at 100 s.
  seek.mutable_seek()->set_position_s(99.9);
  reply = Request(seek);
  ASSERT_TRUE(reply.has_value() && reply->accepted());
  std::optional<wire::TimelineClock> ended = NextClock([](const auto& k) { return !k.playing(); });
  ASSERT_TRUE(ended.has_value());
  EXPECT_NEAR(ended->media_time_s(), 100.0, kTolerance_s);
  EXPECT_NEAR(ended->tracks(0).position_in_table_m().x(), 10.0, kTolerance_m);
}

}  // namespace
}  // namespace sandtable::coordinator
