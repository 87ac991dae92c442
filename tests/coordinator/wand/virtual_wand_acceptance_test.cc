// Acceptance (issue 6): the real program with --virtual-wand paints a stroke through the
// persisted annotation path. The script rests 1.5 s (so the subscriber has joined), then draws
// one stroke with the button held. The test waits (deadlines only) for the published
// stroke_end (published only after it is durable), kills the coordinator with SIGKILL, exports
// the session from the database and checks that the whole stroke is there.
#include <gtest/gtest.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "net/channel.h"
#include "tests/coordinator/membership/child_process.h"
#include "tests/net/test_wait.h"

namespace sandtable {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using testing::ChildProcess;
using testing::ReadReadyLine;
using testing::ReadyString;

constexpr milliseconds kStartDeadline{15000};
constexpr milliseconds kStrokeDeadline{15000};
constexpr milliseconds kReceiveStep{500};

TEST(VirtualWandAcceptanceTest, WandStrokeIsPublishedAndSurvivesSigkill) {
  const fs::path dir =
      fs::temp_directory_path() / ("sandtable_virtual_wand_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path script = dir / "wand.txt", db = dir / "a.db", jsonl = dir / "a.jsonl";
  {
    std::ofstream out(script);
    out << "rate_hz 100\n"
           "at 0.0 -0.2 0.0 0.3 0 0 -1\n"
           "at 1.5 -0.2 0.0 0.3 0 0 -1\n"
           "at 2.0 0.0 0.0 0.3 0 0 -1\n"
           "down 1.5\nup 2.0\n";
  }
  ChildProcess coordinator(
      {SANDTABLE_COORDINATOR_BIN, "--virtual-wand", script.string(), "--annotations", db.string()});
  std::string error;
  const std::optional<nlohmann::json> ready =
      ReadReadyLine(coordinator, "sandtable-coordinator", kStartDeadline, &error);
  ASSERT_TRUE(ready.has_value()) << error;
  zmq::context_t context;
  proto::MessageCounters counters;
  auto sub = net::Socket::Create(&context, net::SocketType::kEventSubscriber);
  ASSERT_TRUE(sub.ok());
  ASSERT_TRUE((*sub)->Connect(ReadyString(*ready, "events")).ok());
  net::Channel channel(std::move(*sub), 952, 1, &counters);

  int begins = 0, points_events = 0;
  std::optional<uint32_t> end_point_count;
  const auto deadline = std::chrono::steady_clock::now() + kStrokeDeadline;
  while (!end_point_count && std::chrono::steady_clock::now() < deadline) {
    std::optional<net::Incoming> in = net::testing::ReceiveWithin(&channel, kReceiveStep);
    if (!in || !in->envelope.has_annotation_event()) continue;
    const wire::AnnotationEvent& e = in->envelope.annotation_event();
    if (e.has_stroke_begin()) ++begins;
    if (e.has_stroke_points()) ++points_events;
    if (e.has_stroke_end()) end_point_count = e.stroke_end().point_count();
  }
  ASSERT_TRUE(end_point_count.has_value()) << "no stroke_end published";
  EXPECT_EQ(begins, 1);
  // 0.2 m in 0.5 s at 100 Hz: 4 mm per sample, every held sample is kept (samples 150..199).
  EXPECT_EQ(*end_point_count, 50u);
  EXPECT_EQ(points_events, 50);
  coordinator.Signal(SIGKILL);
  coordinator.Wait();

  ChildProcess exporter({SANDTABLE_COORDINATOR_BIN, "--annotations", db.string(),
                         "--export-session", jsonl.string()});
  ASSERT_EQ(exporter.Wait(), 0);
  std::ifstream in(jsonl);
  std::string record;
  int exported_begins = 0, exported_points = 0, exported_ends = 0;
  while (std::getline(in, record)) {
    exported_begins += record.find("\"stroke_begin\"") != std::string::npos;
    exported_points += record.find("\"stroke_points\"") != std::string::npos;
    exported_ends += record.find("\"stroke_end\"") != std::string::npos;
  }
  EXPECT_EQ(exported_begins, 1);
  EXPECT_EQ(exported_points, 50);
  EXPECT_EQ(exported_ends, 1);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace sandtable
