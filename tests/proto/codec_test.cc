#include "proto/codec.h"

#include <gtest/gtest.h>

#include <random>
#include <string>

#include "proto/envelope_stamper.h"
#include "proto/sequence_tracker.h"

namespace sandtable::proto {
namespace {

constexpr uint32_t kSenderId = 7;
constexpr uint64_t kIncarnation = 42;

wire::Envelope HeartbeatEnvelope(EnvelopeStamper* stamper) {
  wire::Envelope e = stamper->Next();
  e.mutable_heartbeat()->set_incarnation(kIncarnation);
  return e;
}

TEST(CodecTest, RoundTripsSmallMessageUncompressed) {
  EnvelopeStamper stamper(kSenderId, kIncarnation);
  EncodeInfo info;
  Expected<std::string> bytes = EncodeEnvelope(HeartbeatEnvelope(&stamper), {}, &info);
  ASSERT_TRUE(bytes.ok()) << bytes.status().ToString();
  EXPECT_FALSE(info.compressed);
  EXPECT_EQ(info.wire_bytes, bytes->size());
  MessageCounters counters;
  Expected<wire::Envelope> decoded = DecodeEnvelope(*bytes, {}, &counters);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(decoded->sender_id(), kSenderId);
  EXPECT_EQ(decoded->sequence(), 1u);
  EXPECT_EQ(decoded->heartbeat().incarnation(), kIncarnation);
  EXPECT_EQ(counters.total_rejected(), 0u);
  EXPECT_EQ(BodyName(*decoded), "heartbeat");
}

TEST(CodecTest, CompressesLargeRedundantBodyAndRestoresIt) {
  EnvelopeStamper stamper(kSenderId, kIncarnation);
  wire::Envelope e = stamper.Next();
  auto* capture = e.mutable_capture_reply();
  capture->set_width_px(256);
  capture->set_height_px(256);
  std::string pixels(256 * 256, '\0');
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<char>((i / 256) & 0xF0);
  capture->set_pixels(pixels);
  EncodeInfo info;
  Expected<std::string> bytes = EncodeEnvelope(e, {}, &info);
  ASSERT_TRUE(bytes.ok());
  EXPECT_TRUE(info.compressed);
  EXPECT_LT(bytes->size(), pixels.size() / 10);
  Expected<wire::Envelope> decoded = DecodeEnvelope(*bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(decoded->compression(), wire::COMPRESSION_NONE);
  EXPECT_EQ(decoded->capture_reply().pixels(), pixels);
  EXPECT_EQ(decoded->sender_id(), kSenderId);
  EXPECT_EQ(decoded->sequence(), e.sequence());
}

TEST(CodecTest, LeavesIncompressibleBodyUncompressed) {
  EnvelopeStamper stamper(kSenderId, kIncarnation);
  wire::Envelope e = stamper.Next();
  std::mt19937 rng(3);
  std::string noise(64 * 1024, '\0');
  for (char& c : noise) c = static_cast<char>(rng());
  e.mutable_capture_reply()->set_pixels(noise);
  EncodeInfo info;
  Expected<std::string> bytes = EncodeEnvelope(e, {}, &info);
  ASSERT_TRUE(bytes.ok());
  EXPECT_FALSE(info.compressed);
  EXPECT_TRUE(DecodeEnvelope(*bytes).ok());
}

TEST(CodecTest, RejectsAndCountsBadInput) {
  EnvelopeStamper stamper(kSenderId, kIncarnation);
  const std::string good = *EncodeEnvelope(HeartbeatEnvelope(&stamper));
  MessageCounters counters;

  // Truncated: cut inside the heartbeat body.
  EXPECT_FALSE(DecodeEnvelope(good.substr(0, good.size() - 1), {}, &counters).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kMalformed), 1u);

  // Garbage.
  EXPECT_FALSE(DecodeEnvelope(std::string("\xff\xff\xff\xff\xff", 5), {}, &counters).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kMalformed), 2u);

  // Oversized.
  CodecLimits small;
  small.max_message_bytes = 64;
  EXPECT_FALSE(DecodeEnvelope(std::string(65, '\0'), small, &counters).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kOversized), 1u);

  // Unknown version.
  wire::Envelope v2 = HeartbeatEnvelope(&stamper);
  v2.set_protocol_version(kProtocolVersion + 1);
  Expected<wire::Envelope> r = DecodeEnvelope(v2.SerializeAsString(), {}, &counters);
  EXPECT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("protocol_version"), std::string::npos);
  EXPECT_EQ(counters.rejected(RejectReason::kWrongVersion), 1u);

  // No sequence number.
  wire::Envelope no_seq = HeartbeatEnvelope(&stamper);
  no_seq.clear_sequence();
  EXPECT_FALSE(DecodeEnvelope(no_seq.SerializeAsString(), {}, &counters).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kMalformed), 3u);

  // No body.
  wire::Envelope empty = stamper.Next();
  EXPECT_FALSE(DecodeEnvelope(empty.SerializeAsString(), {}, &counters).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kEmptyBody), 1u);

  // Unknown body type from a newer sender: field 999 of type varint.
  std::string unknown = stamper.Next().SerializeAsString();
  unknown += std::string("\xb8\x3e\x01", 3);  // tag (999 << 3 | 0) = 7992 as varint, value 1
  EXPECT_FALSE(DecodeEnvelope(unknown, {}, &counters).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kUnknownType), 1u);

  EXPECT_EQ(counters.total_rejected(), 7u);
}

TEST(CodecTest, RejectsCompressionBombsAndCorruptStreams) {
  EnvelopeStamper stamper(kSenderId, kIncarnation);
  MessageCounters counters;
  CodecLimits limits;
  limits.max_body_bytes = 1 << 20;

  wire::Envelope bomb = stamper.Next();
  bomb.set_compression(wire::COMPRESSION_ZLIB);
  bomb.set_body_size_bytes(2u << 20);
  bomb.set_compressed_body("x");
  EXPECT_FALSE(DecodeEnvelope(bomb.SerializeAsString(), limits, &counters).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kOversized), 1u);

  wire::Envelope corrupt = stamper.Next();
  corrupt.set_compression(wire::COMPRESSION_ZLIB);
  corrupt.set_body_size_bytes(100);
  corrupt.set_compressed_body("not zlib at all");
  EXPECT_FALSE(DecodeEnvelope(corrupt.SerializeAsString(), limits, &counters).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kBadCompression), 1u);

  wire::Envelope unknown_codec = HeartbeatEnvelope(&stamper);
  unknown_codec.set_compression(static_cast<wire::Compression>(9));
  EXPECT_FALSE(DecodeEnvelope(unknown_codec.SerializeAsString(), limits, &counters).ok());
  EXPECT_EQ(counters.rejected(RejectReason::kBadCompression), 2u);
}

TEST(CodecTest, EncodeRefusesMessagesOverTheLimitAndWithoutBody) {
  EnvelopeStamper stamper(kSenderId, kIncarnation);
  EXPECT_FALSE(EncodeEnvelope(stamper.Next()).ok());
  wire::Envelope big = stamper.Next();
  std::mt19937 rng(5);
  std::string noise(8192, '\0');
  for (char& c : noise) c = static_cast<char>(rng());
  big.mutable_set_frame_request()->set_pixels(noise);
  CodecLimits limits;
  limits.max_message_bytes = 4096;
  EXPECT_FALSE(EncodeEnvelope(big, limits).ok());
}

TEST(SequenceTrackerTest, RejectsDuplicatesAndReorderingButAcceptsRestart) {
  EnvelopeStamper first(kSenderId, 1);
  SequenceTracker tracker;
  MessageCounters counters;
  const wire::Envelope a = HeartbeatEnvelope(&first);
  const wire::Envelope b = HeartbeatEnvelope(&first);
  const wire::Envelope c = HeartbeatEnvelope(&first);
  EXPECT_TRUE(tracker.Accept(a, &counters).ok());
  EXPECT_TRUE(tracker.Accept(c, &counters).ok());
  EXPECT_FALSE(tracker.Accept(b, &counters).ok());  // older than c
  EXPECT_FALSE(tracker.Accept(c, &counters).ok());  // duplicate
  EXPECT_EQ(counters.rejected(RejectReason::kOutOfOrder), 2u);
  EXPECT_EQ(tracker.missed(), 1u);  // b never arrived in order

  EnvelopeStamper restarted(kSenderId, 2);
  EXPECT_TRUE(tracker.Accept(HeartbeatEnvelope(&restarted), &counters).ok());
}

TEST(CodecLimitsTest, CheckNamesBadFields) {
  CodecLimits limits;
  EXPECT_TRUE(limits.Check().ok());
  limits.zlib_level = 0;
  EXPECT_NE(limits.Check().message().find("zlib_level"), std::string::npos);
}

}  // namespace
}  // namespace sandtable::proto
