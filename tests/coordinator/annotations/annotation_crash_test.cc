// Acceptance (issue 6): a coordinator killed with SIGKILL in the middle of a stroke and
// restarted has lost no acknowledged annotation event.
//
// A client process (this test) sends a stroke point by point to sandtable-coordinator
// (--annotations FILE) with up to kWindow requests in flight, and records every accepted ack.
// After kAcksBeforeKill acks the coordinator gets SIGKILL while requests are still in flight.
// It is restarted on the same database; a catch-up request from 0 returns a snapshot, which
// must hold every acknowledged point (in order, same values), and its last event sequence
// must be at least the largest acknowledged one. Also: a second client joining late with
// last_seen_sequence gets exactly the events after it; a damaged database makes the
// coordinator refuse to start with exit code 2 (no crash).
// Waits on events with deadlines; never sleeps for synchronisation.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>

#include "net/channel.h"
#include "tests/cluster/annotation_test_util.h"
#include "tests/coordinator/membership/child_process.h"
#include "tests/net/test_wait.h"

namespace sandtable {
namespace {

namespace fs = std::filesystem;
using cluster::testing::Begin;
using cluster::testing::LinePoint;
using cluster::testing::Points;
using std::chrono::milliseconds;
using testing::ChildProcess;
using testing::ReadReadyLine;
using testing::ReadyString;

constexpr milliseconds kStartDeadline{15000};
constexpr milliseconds kReplyDeadline{10000};
constexpr int kWindow = 16;
constexpr int kAcksBeforeKill = 150;
constexpr uint64_t kStrokeId = 42;

class Client {
 public:
  explicit Client(const std::string& requests, uint32_t id) {
    auto dealer = net::Socket::Create(&context_, net::SocketType::kDealer);
    EXPECT_TRUE(dealer.ok());
    EXPECT_TRUE((*dealer)->Connect(requests).ok());
    channel_ = std::make_unique<net::Channel>(std::move(*dealer), id, 1, &counters_);
  }
  // Sends a request; returns its envelope sequence.
  uint64_t Send(wire::Envelope envelope) {
    EXPECT_TRUE(channel_->Send(std::move(envelope)).ok());
    return ++sent_;
  }
  std::optional<wire::Envelope> Receive(milliseconds deadline) {
    std::optional<net::Incoming> in = net::testing::ReceiveWithin(channel_.get(), deadline);
    if (!in) return std::nullopt;
    return std::move(in->envelope);
  }
  wire::CatchUpReply CatchUp(uint64_t last_seen) {
    wire::Envelope request;
    request.mutable_catch_up_request()->set_last_seen_sequence(last_seen);
    Send(std::move(request));
    while (std::optional<wire::Envelope> reply = Receive(kReplyDeadline)) {
      if (reply->has_catch_up_reply()) return reply->catch_up_reply();
    }
    ADD_FAILURE() << "no catch-up reply";
    return {};
  }

 private:
  zmq::context_t context_;
  proto::MessageCounters counters_;
  std::unique_ptr<net::Channel> channel_;
  uint64_t sent_ = 0;
};

class AnnotationCrashTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("sandtable_crash_test_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    db_ = (dir_ / "annotations.db").string();
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::unique_ptr<ChildProcess> Start(std::string* requests) {
    auto child = std::make_unique<ChildProcess>(
        std::vector<std::string>{SANDTABLE_COORDINATOR_BIN, "--annotations", db_});
    std::string error;
    const std::optional<nlohmann::json> ready =
        ReadReadyLine(*child, "sandtable-coordinator", kStartDeadline, &error);
    EXPECT_TRUE(ready.has_value()) << error;
    if (ready) *requests = ReadyString(*ready, "requests");
    return child;
  }

  fs::path dir_;
  std::string db_;
};

TEST_F(AnnotationCrashTest, SigkillMidStrokeLosesNoAcknowledgedEvent) {
  std::string requests;
  std::unique_ptr<ChildProcess> coordinator = Start(&requests);
  ASSERT_FALSE(requests.empty());
  Client client(requests, 7001);

  std::map<uint64_t, int> point_of_request;  // envelope sequence -> point index
  std::map<int, uint64_t> acked_points;      // point index -> event sequence
  uint64_t begin_event = 0, max_acked_event = 0;
  {
    wire::Envelope e;
    *e.mutable_annotation_request() = Begin(kStrokeId, 0.f, 0.f, 1.f);
    const uint64_t seq = client.Send(std::move(e));
    std::optional<wire::Envelope> ack = client.Receive(kReplyDeadline);
    ASSERT_TRUE(ack && ack->has_annotation_ack());
    ASSERT_EQ(ack->annotation_ack().request_sequence(), seq);
    ASSERT_TRUE(ack->annotation_ack().accepted()) << ack->annotation_ack().reason();
    begin_event = ack->annotation_ack().event_sequence();
  }
  auto record = [&](const wire::Envelope& reply) {
    if (!reply.has_annotation_ack()) return;
    const wire::AnnotationAck& ack = reply.annotation_ack();
    ASSERT_TRUE(ack.accepted()) << ack.reason();
    acked_points[point_of_request.at(ack.request_sequence())] = ack.event_sequence();
    max_acked_event = std::max(max_acked_event, ack.event_sequence());
  };
  int next_point = 0;
  size_t in_flight = 0;
  while (static_cast<int>(acked_points.size()) < kAcksBeforeKill) {
    while (in_flight < kWindow) {
      wire::Envelope e;
      *e.mutable_annotation_request() = Points(kStrokeId, next_point, {LinePoint(next_point)});
      point_of_request[client.Send(std::move(e))] = next_point++;
      ++in_flight;
    }
    std::optional<wire::Envelope> reply = client.Receive(kReplyDeadline);
    ASSERT_TRUE(reply.has_value()) << "no ack within the deadline";
    record(*reply);
    --in_flight;
  }
  // Kill with requests in flight (the window is full again before the kill).
  while (in_flight < kWindow) {
    wire::Envelope e;
    *e.mutable_annotation_request() = Points(kStrokeId, next_point, {LinePoint(next_point)});
    point_of_request[client.Send(std::move(e))] = next_point++;
    ++in_flight;
  }
  coordinator->Signal(SIGKILL);
  EXPECT_EQ(coordinator->Wait(), 128 + SIGKILL);
  // Acks that were sent before death may still be queued here: count them too.
  while (std::optional<wire::Envelope> reply = client.Receive(milliseconds(200))) record(*reply);
  const size_t acked = acked_points.size();
  ASSERT_GE(acked, static_cast<size_t>(kAcksBeforeKill));
  // Acks arrive in order, so the acknowledged points are 0 .. acked-1.
  ASSERT_EQ(acked_points.rbegin()->first, static_cast<int>(acked) - 1);

  std::string requests2;
  std::unique_ptr<ChildProcess> restarted = Start(&requests2);
  ASSERT_FALSE(requests2.empty());
  Client late(requests2, 7002);
  const wire::CatchUpReply reply = late.CatchUp(0);
  ASSERT_TRUE(reply.snapshot_sent());
  EXPECT_GE(reply.last_event_sequence(), max_acked_event);
  const wire::Snapshot& snap = reply.snapshot();
  ASSERT_EQ(snap.strokes_size(), 1);
  EXPECT_EQ(snap.strokes(0).begin().stroke_id(), kStrokeId);
  EXPECT_FALSE(snap.strokes(0).ended());
  const int restored = snap.strokes(0).points_in_table_m_size() / 3;
  std::cout << "acknowledged points " << acked << " (events 1.." << max_acked_event << "), sent "
            << next_point << ", restored " << restored << "\n";
  ASSERT_GE(restored, static_cast<int>(acked)) << "an acknowledged event was lost";
  for (int k = 0; k < restored; ++k) {
    const Eigen::Vector3f p = LinePoint(k);
    ASSERT_EQ(snap.strokes(0).points_in_table_m(3 * k), p.x()) << "point " << k;
    ASSERT_EQ(snap.strokes(0).points_in_table_m(3 * k + 1), p.y());
    ASSERT_EQ(snap.strokes(0).points_in_table_m(3 * k + 2), p.z());
  }
  // Catch-up from a known sequence: exactly the events after it, in order.
  const wire::CatchUpReply tail = late.CatchUp(begin_event + 10);
  ASSERT_FALSE(tail.snapshot_sent());
  ASSERT_EQ(tail.events_size(), static_cast<int>(reply.last_event_sequence() - begin_event - 10));
  for (int i = 0; i < tail.events_size(); ++i) {
    EXPECT_EQ(tail.events(i).event_sequence(), begin_event + 11 + i);
  }
  // The stroke goes on after the restart (the next point index is the restored count).
  wire::Envelope more;
  *more.mutable_annotation_request() = Points(kStrokeId, restored, {LinePoint(restored)});
  late.Send(std::move(more));
  std::optional<wire::Envelope> ack = late.Receive(kReplyDeadline);
  ASSERT_TRUE(ack && ack->has_annotation_ack());
  EXPECT_TRUE(ack->annotation_ack().accepted()) << ack->annotation_ack().reason();
  restarted->Signal(SIGTERM);
  EXPECT_EQ(restarted->Wait(), 0);
}

// Runs a coordinator on the database, gets `points` acknowledged points of one stroke and
// kills it with SIGKILL (its -wal file then holds the newest events). Returns the largest
// acknowledged event sequence.
uint64_t AckThenKill(AnnotationCrashTest* test, int points,
                     const std::function<std::unique_ptr<ChildProcess>(std::string*)>& start) {
  std::string requests;
  std::unique_ptr<ChildProcess> coordinator = start(&requests);
  EXPECT_FALSE(requests.empty());
  if (requests.empty()) return 0;
  Client client(requests, 7003);
  uint64_t max_acked = 0;
  for (int k = -1; k < points; ++k) {
    wire::Envelope e;
    *e.mutable_annotation_request() =
        k < 0 ? Begin(kStrokeId, 0.f, 0.f, 1.f) : Points(kStrokeId, k, {LinePoint(k)});
    client.Send(std::move(e));
    std::optional<wire::Envelope> ack = client.Receive(kReplyDeadline);
    EXPECT_TRUE(ack && ack->has_annotation_ack() && ack->annotation_ack().accepted());
    if (!ack || !ack->has_annotation_ack()) return max_acked;
    max_acked = std::max(max_acked, ack->annotation_ack().event_sequence());
  }
  coordinator->Signal(SIGKILL);
  EXPECT_EQ(coordinator->Wait(), 128 + SIGKILL);
  (void)test;
  return max_acked;
}

// The whole output of a coordinator that must refuse to start, and its exit status.
std::pair<int, std::string> RunToExit(const std::vector<std::string>& argv) {
  ChildProcess child(argv, testing::ChildOutput::kStdoutAndStderr);
  std::string out;
  while (std::optional<std::string> line = child.ReadLine(kStartDeadline)) out += *line + "\n";
  return {child.Wait(), out};
}

TEST_F(AnnotationCrashTest, DeletedOrCutWalAfterSigkillIsDetectedAndNamed) {
  auto start = [&](std::string* requests) { return Start(requests); };
  for (const std::string damage : {"delete", "truncate"}) {
    fs::remove(db_);
    fs::remove(db_ + ".seq");
    const uint64_t acked = AckThenKill(this, 60, start);
    ASSERT_EQ(acked, 61u);
    const std::string wal = db_ + "-wal";
    ASSERT_TRUE(fs::exists(wal)) << "no -wal after SIGKILL";
    if (damage == "delete") {
      fs::remove(wal);
    } else {
      fs::resize_file(wal, fs::file_size(wal) / 2);
    }
    const auto [code, out] = RunToExit({SANDTABLE_COORDINATOR_BIN, "--annotations", db_});
    std::cout << damage << " -wal: exit " << code << ": " << out;
    EXPECT_EQ(code, 2) << out;
    EXPECT_NE(out.find("are missing"), std::string::npos) << out;
    EXPECT_NE(out.find("61 events were acknowledged"), std::string::npos) << out;
    EXPECT_NE(out.find("-wal"), std::string::npos) << out;
    EXPECT_NE(out.find("--annotations-accept-loss"), std::string::npos) << out;
    EXPECT_EQ(out.find("\"ready\""), std::string::npos) << "it started: " << out;
  }
  // Accepting the loss explicitly: it starts (and says so); a later start is normal again.
  ChildProcess accepted(
      {SANDTABLE_COORDINATOR_BIN, "--annotations", db_, "--annotations-accept-loss"});
  std::string error;
  ASSERT_TRUE(ReadReadyLine(accepted, "sandtable-coordinator", kStartDeadline, &error)) << error;
  accepted.Signal(SIGTERM);
  EXPECT_EQ(accepted.Wait(), 0);
  std::string requests;
  std::unique_ptr<ChildProcess> again = Start(&requests);
  EXPECT_FALSE(requests.empty());
}

TEST_F(AnnotationCrashTest, ChangedRowIsDetectedAtStartAndNamed) {
  auto start = [&](std::string* requests) { return Start(requests); };
  ASSERT_EQ(AckThenKill(this, 20, start), 21u);
  // A clean start and stop checkpoints the -wal into the main file, so an edit of the file
  // itself reaches the rows.
  {
    std::string requests;
    std::unique_ptr<ChildProcess> clean = Start(&requests);
    clean->Signal(SIGTERM);
    ASSERT_EQ(clean->Wait(), 0);
  }
  // One byte of the stored points flipped in place (a float of event 12's body), no tool.
  std::string bytes;
  {
    std::ifstream in(db_, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  wire::AnnotationEvent twelve = Points(kStrokeId, 10, {LinePoint(10)});
  const std::string floats = twelve.stroke_points().SerializeAsString().substr(
      twelve.stroke_points().SerializeAsString().size() - 12);
  const size_t at = bytes.find(floats);
  ASSERT_NE(at, std::string::npos) << "event 12's points not found in the file";
  bytes[at + 5] = static_cast<char>(bytes[at + 5] ^ 0x10);
  std::ofstream(db_, std::ios::binary | std::ios::trunc) << bytes;
  const auto [code, out] = RunToExit({SANDTABLE_COORDINATOR_BIN, "--annotations", db_});
  std::cout << "changed row: exit " << code << ": " << out;
  EXPECT_EQ(code, 2) << out;
  EXPECT_NE(out.find("event 12"), std::string::npos) << out;
  EXPECT_NE(out.find("checksum mismatch"), std::string::npos) << out;
}

TEST_F(AnnotationCrashTest, SecondCoordinatorOnTheSameDatabaseIsRefused) {
  std::string requests;
  std::unique_ptr<ChildProcess> first = Start(&requests);
  ASSERT_FALSE(requests.empty());
  const auto [code, out] = RunToExit({SANDTABLE_COORDINATOR_BIN, "--annotations", db_});
  EXPECT_EQ(code, 2) << out;
  EXPECT_NE(out.find("in use by another coordinator (pid " + std::to_string(first->pid())),
            std::string::npos)
      << out;
  // The first one still serves.
  Client client(requests, 7004);
  EXPECT_EQ(client.CatchUp(0).last_event_sequence(), 0u);
  first->Signal(SIGTERM);
  EXPECT_EQ(first->Wait(), 0);
}

TEST_F(AnnotationCrashTest, ImportOfACutSessionFileExitsTwoAndImportsNothing) {
  const std::string session = (dir_ / "cut.jsonl").string();
  std::ofstream(session) << "{\"format\":\"sandtable-annotation-session\",\"version\":1,"
                            "\"event_count\":8}\n"
                         << "{\"kind\":\"stroke_begin\",\"stroke_id\":1,\"color_rgb\":[1,0,0],"
                            "\"width_m\":0.004}\n"
                         << "{\"kind\":\"stroke_points\",\"stroke_id\":1,\"first_point_index\":0,"
                            "\"points_in_table_m\":[[0.1,0.2,0]]}\n"
                         << "{\"kind\":\"stroke_end\",\"stroke_id\":1,\"point_count\":1}\n";
  const auto [code, out] =
      RunToExit({SANDTABLE_COORDINATOR_BIN, "--annotations", db_, "--import-session", session});
  EXPECT_EQ(code, 2) << out;
  EXPECT_NE(out.find("line 1 (header): event_count 8 but the file holds 3"), std::string::npos)
      << out;
  const auto [export_code, export_out] =
      RunToExit({SANDTABLE_COORDINATOR_BIN, "--annotations", db_, "--export-session",
                 (dir_ / "out.jsonl").string()});
  EXPECT_EQ(export_code, 0) << export_out;
  EXPECT_NE(export_out.find("exported 0 events"), std::string::npos) << export_out;
}

TEST_F(AnnotationCrashTest, DamagedDatabaseRefusesToStartWithAMessage) {
  std::ofstream(db_, std::ios::binary) << std::string(4096, '\x5a');
  ChildProcess child({SANDTABLE_COORDINATOR_BIN, "--annotations", db_});
  EXPECT_FALSE(child.ReadLine(kStartDeadline).has_value());  // no endpoints line
  EXPECT_EQ(child.Wait(), 2);  // a clean refusal, not a crash (128 + signal)
}

}  // namespace
}  // namespace sandtable
