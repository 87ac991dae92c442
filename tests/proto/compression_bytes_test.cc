// Measures bytes on the wire per exchange for representative payloads, with the default codec
// limits (zlib level 1, compress from 4 KiB when it saves >= 10 %). Prints a table (the
// numbers quoted in docs/protocol.md) and checks that compression is used where it pays and
// that every payload round-trips.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "proto/codec.h"
#include "proto/envelope_stamper.h"

namespace sandtable::proto {
namespace {

constexpr int kWidth_px = 1280;
constexpr int kHeight_px = 800;

struct Row {
  const char* name;
  wire::Envelope envelope;
};

// A Gray-code column pattern (bit 5) as a projector shows it.
std::string GrayCodeFrame() {
  std::string pixels(static_cast<size_t>(kWidth_px) * kHeight_px, '\0');
  for (int y = 0; y < kHeight_px; ++y) {
    for (int x = 0; x < kWidth_px; ++x) {
      const int gray = x ^ (x >> 1);
      pixels[static_cast<size_t>(y) * kWidth_px + x] = ((gray >> 5) & 1) ? '\xff' : '\0';
    }
  }
  return pixels;
}

// The same pattern seen by a camera: perspective-ish warp, falloff, sensor noise (sigma 2 DN).
std::string CameraCapture() {
  std::mt19937 rng(17);
  std::normal_distribution<double> noise(0.0, 2.0);
  std::string pixels(static_cast<size_t>(kWidth_px) * kHeight_px, '\0');
  for (int y = 0; y < kHeight_px; ++y) {
    for (int x = 0; x < kWidth_px; ++x) {
      const double u = x * (0.9 + 0.2 * y / kHeight_px);
      const int gray = static_cast<int>(u) ^ (static_cast<int>(u) >> 1);
      const double falloff = 0.6 + 0.4 * std::cos((x - 640.0) / 1400.0);
      const double v = (((gray >> 5) & 1) ? 200.0 : 20.0) * falloff + noise(rng);
      pixels[static_cast<size_t>(y) * kWidth_px + x] = static_cast<char>(std::clamp(v, 0.0, 255.0));
    }
  }
  return pixels;
}

TEST(CompressionBytesTest, ReportsBytesPerExchange) {
  EnvelopeStamper stamper(3, 1);
  std::vector<Row> rows;

  wire::Envelope heartbeat = stamper.Next();
  heartbeat.mutable_heartbeat()->set_incarnation(123456789);
  rows.push_back({"heartbeat", heartbeat});

  wire::Envelope members = stamper.Next();
  for (uint32_t i = 1; i <= 8; ++i) {
    auto* m = members.mutable_member_list()->add_members();
    m->set_node_id(i);
    m->set_incarnation(1000 + i);
    m->mutable_endpoints()->set_peer_router("tcp://127.0.0.1:4" + std::to_string(1000 + i));
  }
  rows.push_back({"member_list (8 nodes)", members});

  wire::Envelope frame = stamper.Next();
  frame.mutable_set_frame_request()->set_width_px(kWidth_px);
  frame.mutable_set_frame_request()->set_height_px(kHeight_px);
  frame.mutable_set_frame_request()->set_encoding(wire::PIXEL_ENCODING_GRAY8);
  frame.mutable_set_frame_request()->set_pixels(GrayCodeFrame());
  rows.push_back({"set_frame 1280x800 gray8 Gray code", frame});

  wire::Envelope capture = stamper.Next();
  capture.mutable_capture_reply()->set_width_px(kWidth_px);
  capture.mutable_capture_reply()->set_height_px(kHeight_px);
  capture.mutable_capture_reply()->set_bit_depth(8);
  capture.mutable_capture_reply()->set_pixels(CameraCapture());
  rows.push_back({"capture_reply 1280x800 gray8 noisy", capture});

  // A distance field of a 1280 x 800 projector at an 8 px step (161 x 101 points).
  wire::Envelope overlap = stamper.Next();
  auto* share = overlap.mutable_blend_share();
  share->set_step_px(8);
  share->set_cols(161);
  share->set_rows(101);
  for (int y = 0; y < 101; ++y) {
    for (int x = 0; x < 161; ++x) {
      const float d = static_cast<float>(std::min({x, y, 160 - x, 100 - y}) * 0.0095);
      share->add_distance_m(d);
    }
  }
  rows.push_back({"blend_share 161x101 float", overlap});

  std::printf("%-40s %12s %12s %s\n", "exchange", "body_bytes", "wire_bytes", "compressed");
  for (const Row& row : rows) {
    EncodeInfo info;
    Expected<std::string> bytes = EncodeEnvelope(row.envelope, {}, &info);
    ASSERT_TRUE(bytes.ok()) << row.name << ": " << bytes.status().ToString();
    std::printf("%-40s %12zu %12zu %s\n", row.name, info.body_bytes, info.wire_bytes,
                info.compressed ? "zlib" : "no");
    Expected<wire::Envelope> back = DecodeEnvelope(*bytes);
    ASSERT_TRUE(back.ok()) << row.name << ": " << back.status().ToString();
    EXPECT_EQ(back->SerializeAsString(), row.envelope.SerializeAsString()) << row.name;
    if (std::string(row.name).rfind("set_frame", 0) == 0) {
      EXPECT_TRUE(info.compressed);
      EXPECT_LT(info.wire_bytes, info.body_bytes / 20) << "a stripe pattern must shrink > 20x";
    }
    if (std::string(row.name) == "heartbeat") {
      EXPECT_FALSE(info.compressed);
    }
  }
}

}  // namespace
}  // namespace sandtable::proto
