#include "net/channel.h"

#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "tests/net/test_wait.h"

namespace sandtable::net {
namespace {

using std::chrono::milliseconds;
using testing::ReceiveWithin;
// Generous: a loaded 2-core CI machine; the messages normally arrive in well under 1 ms.
constexpr milliseconds kDeadline{5000};

struct Pair {
  zmq::context_t context;
  proto::MessageCounters server_counters, client_counters;
  std::unique_ptr<Channel> server, client;
  std::string endpoint;
};

std::unique_ptr<Pair> MakePair() {
  auto p = std::make_unique<Pair>();
  auto router = Socket::Create(&p->context, SocketType::kRouter);
  EXPECT_TRUE(router.ok());
  Expected<std::string> endpoint = (*router)->Bind("tcp://127.0.0.1:*");
  EXPECT_TRUE(endpoint.ok()) << endpoint.status().ToString();
  p->endpoint = *endpoint;
  auto dealer = Socket::Create(&p->context, SocketType::kDealer);
  EXPECT_TRUE((*dealer)->Connect(p->endpoint).ok());
  p->server = std::make_unique<Channel>(std::move(*router), 0, 1, &p->server_counters);
  p->client = std::make_unique<Channel>(std::move(*dealer), 5, 9, &p->client_counters);
  return p;
}

TEST(SocketTest, BindToPortZeroReportsTheRealPort) {
  zmq::context_t context;
  auto router = Socket::Create(&context, SocketType::kRouter);
  ASSERT_TRUE(router.ok());
  Expected<std::string> endpoint = (*router)->Bind("tcp://127.0.0.1:*");
  ASSERT_TRUE(endpoint.ok());
  EXPECT_EQ(endpoint->rfind("tcp://127.0.0.1:", 0), 0u);
  const int port = std::stoi(endpoint->substr(endpoint->rfind(':') + 1));
  EXPECT_GT(port, 0);
  // Binding the same port again fails with a Status, not an exception.
  auto other = Socket::Create(&context, SocketType::kRouter);
  Expected<std::string> again = (*other)->Bind(*endpoint);
  EXPECT_FALSE(again.ok());
  EXPECT_EQ(again.status().code(), StatusCode::kUnavailable);
  EXPECT_FALSE((*other)->Bind("nonsense://x").ok());
  EXPECT_FALSE((*other)->Connect("tcp://").ok());
}

TEST(ChannelTest, RequestReplyRoundTrip) {
  auto p = MakePair();
  wire::Envelope hello;
  hello.mutable_hello()->set_incarnation(9);
  ASSERT_TRUE(p->client->Send(hello).ok());
  std::optional<Incoming> in = ReceiveWithin(p->server.get(), kDeadline);
  ASSERT_TRUE(in.has_value());
  EXPECT_EQ(in->envelope.sender_id(), 5u);
  EXPECT_TRUE(in->envelope.has_hello());
  wire::Envelope ack;
  ack.mutable_hello_ack()->set_accepted(true);
  ASSERT_TRUE(p->server->Send(ack, in->routing_id).ok());
  std::optional<Incoming> reply = ReceiveWithin(p->client.get(), kDeadline);
  ASSERT_TRUE(reply.has_value());
  EXPECT_TRUE(reply->envelope.hello_ack().accepted());
  // Sending to a routing id that is not connected is a Status, not an exception.
  EXPECT_EQ(p->server->Send(ack, "nobody").code(), StatusCode::kNotFound);
}

TEST(ChannelTest, BadInputIsRejectedCountedAndTheChannelKeepsWorking) {
  auto p = MakePair();
  auto raw = Socket::Create(&p->context, SocketType::kDealer);
  ASSERT_TRUE((*raw)->Connect(p->endpoint).ok());
  proto::EnvelopeStamper stamper(77, 1);

  wire::Envelope good = stamper.Next();
  good.mutable_heartbeat();
  const std::string good_bytes = *proto::EncodeEnvelope(good);
  wire::Envelope old_version = stamper.Next();
  old_version.mutable_heartbeat();
  old_version.set_protocol_version(proto::kProtocolVersion + 7);

  ASSERT_TRUE((*raw)->Send({good_bytes.substr(0, good_bytes.size() - 2)}).ok());     // truncated
  ASSERT_TRUE((*raw)->Send({std::string("\x0a\xff\xff\xff\xff\xff\xff", 7)}).ok());  // garbage
  ASSERT_TRUE((*raw)->Send({old_version.SerializeAsString()}).ok());
  ASSERT_TRUE((*raw)->Send({good_bytes, good_bytes}).ok());  // wrong frame count
  ASSERT_TRUE((*raw)->Send({good_bytes}).ok());              // valid
  ASSERT_TRUE((*raw)->Send({good_bytes}).ok());              // replayed duplicate

  std::optional<Incoming> in = ReceiveWithin(p->server.get(), kDeadline);
  ASSERT_TRUE(in.has_value());
  EXPECT_EQ(in->envelope.sender_id(), 77u);
  ASSERT_TRUE(testing::WaitFor(
      [&] {
        (void)p->server->TryReceive();
        return p->server_counters.total_rejected() == 5;
      },
      kDeadline))
      << p->server_counters.ToString();
  EXPECT_EQ(p->server_counters.rejected(proto::RejectReason::kMalformed), 3u);
  EXPECT_EQ(p->server_counters.rejected(proto::RejectReason::kWrongVersion), 1u);
  EXPECT_EQ(p->server_counters.rejected(proto::RejectReason::kOutOfOrder), 1u);
  EXPECT_EQ(p->server_counters.accepted(), 1u);
}

TEST(ChannelTest, LargePayloadTravelsCompressed) {
  auto p = MakePair();
  wire::Envelope capture;
  capture.mutable_capture_reply()->set_pixels(std::string(1 << 20, '\x10'));
  ASSERT_TRUE(p->client->Send(capture).ok());
  std::optional<Incoming> in = ReceiveWithin(p->server.get(), kDeadline);
  ASSERT_TRUE(in.has_value());
  EXPECT_EQ(in->envelope.capture_reply().pixels().size(), size_t{1} << 20);
  EXPECT_LT(in->wire_bytes, size_t{1} << 14);
  EXPECT_EQ(p->client->stats().bytes_sent, in->wire_bytes);
}

// Fault injection (lab chaos): of 200 messages a seeded share is dropped and a share
// corrupted; everything not dropped reaches the receiver, which accepts or refuses it (a flipped
// byte inside a value can still decode); the same seed draws the same faults.
TEST(ChannelTest, InjectedFaultsDropAndCorruptASeededShare) {
  constexpr int kMessages = 200;
  auto run = [](uint64_t seed) {
    auto p = MakePair();
    EXPECT_TRUE(p->client->SetFaults({0.3, 0.2, seed}).ok());
    for (int i = 0; i < kMessages; ++i) {
      wire::Envelope e;
      e.mutable_heartbeat()->set_incarnation(static_cast<uint64_t>(i));
      EXPECT_TRUE(p->client->Send(std::move(e)).ok());
    }
    const ChannelFaultCounts counts = p->client->fault_counts();
    const uint64_t delivered = kMessages - counts.dropped;
    EXPECT_TRUE(testing::WaitFor(
        [&] {
          (void)p->server->TryReceive();
          return p->server_counters.accepted() + p->server_counters.total_rejected() == delivered;
        },
        kDeadline))
        << p->server_counters.ToString() << " dropped " << counts.dropped;
    EXPECT_GT(p->server_counters.total_rejected(), 0u);  // some corruption is caught
    EXPECT_LE(p->server_counters.total_rejected(), counts.corrupted + 0u);
    return counts;
  };
  const ChannelFaultCounts a = run(7), b = run(7);
  EXPECT_EQ(a.dropped, b.dropped);
  EXPECT_EQ(a.corrupted, b.corrupted);
  // 30 % and 20 % of 200: well inside 4 standard deviations.
  EXPECT_NEAR(static_cast<double>(a.dropped), 60.0, 26.0);
  EXPECT_NEAR(static_cast<double>(a.corrupted), 40.0, 23.0);

  auto p = MakePair();
  EXPECT_FALSE(p->client->SetFaults({0.8, 0.3, 1}).ok());
  EXPECT_FALSE(p->client->SetFaults({-0.1, 0.0, 1}).ok());
  ASSERT_TRUE(p->client->SetFaults({1.0, 0.0, 1}).ok());
  wire::Envelope e;
  e.mutable_heartbeat();
  EXPECT_TRUE(p->client->Send(std::move(e)).ok());  // a lossy link: the sender cannot tell
  EXPECT_EQ(p->client->fault_counts().dropped, 1u);
  EXPECT_FALSE(ReceiveWithin(p->server.get(), milliseconds(300)).has_value());
}

// Injected latency: every message arrives no sooner than the delay minus the jitter after it was
// sent, held until FlushDelayed finds it due, and in the order sent.
TEST(ChannelTest, InjectedLatencyHoldsEachMessageAndKeepsTheOrder) {
  auto p = MakePair();
  ChannelFaults faults;
  faults.delay = std::chrono::milliseconds(50);
  faults.jitter = std::chrono::milliseconds(10);
  faults.seed = 3;
  ASSERT_TRUE(p->client->SetFaults(faults).ok());
  constexpr int kMessages = 20;
  const auto sent_at = std::chrono::steady_clock::now();
  for (int i = 0; i < kMessages; ++i) {
    wire::Envelope e;
    e.mutable_time_request()->set_t0_client_send_ns(i);
    ASSERT_TRUE(p->client->Send(std::move(e)).ok());
  }
  EXPECT_EQ(p->client->fault_counts().delayed, static_cast<uint64_t>(kMessages));
  ASSERT_TRUE(p->client->next_delayed_due().has_value());
  EXPECT_GE(*p->client->next_delayed_due(), sent_at + faults.delay - faults.jitter);
  // Nothing leaves before it is due.
  p->client->FlushDelayed(sent_at);
  EXPECT_FALSE(ReceiveWithin(p->server.get(), milliseconds(20)).has_value());
  int received = 0;
  const auto until = std::chrono::steady_clock::now() + kDeadline;
  while (received < kMessages && std::chrono::steady_clock::now() < until) {
    p->client->FlushDelayed(std::chrono::steady_clock::now());
    std::optional<Incoming> in = ReceiveWithin(p->server.get(), milliseconds(5));
    if (!in) continue;
    EXPECT_GE(std::chrono::steady_clock::now(), sent_at + faults.delay - faults.jitter);
    EXPECT_EQ(in->envelope.time_request().t0_client_send_ns(), received) << "out of order";
    ++received;
  }
  EXPECT_EQ(received, kMessages);
  EXPECT_FALSE(p->client->next_delayed_due().has_value());
  ChannelFaults bad;
  bad.delay = std::chrono::milliseconds(5);
  bad.jitter = std::chrono::milliseconds(6);
  EXPECT_FALSE(bad.Check().ok()) << "jitter larger than the delay";
}

}  // namespace
}  // namespace sandtable::net
