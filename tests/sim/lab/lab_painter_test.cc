// LabPainter (the chaos runs' annotation client) against a real coordinator in this process
// (CoordinatorServer + AnnotationService on a SQLite file, loopback TCP). A coordinator that goes
// away with requests in flight (its sockets closed, as its death closes them) and comes back on
// the same endpoint and database: the painter notices the dropped connection at once instead of
// waiting out its ack timeout, paints on in a new stroke, and every point acknowledged is in the
// database afterwards.
#include "sim/lab/lab_painter.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>

#include "coordinator/annotations/annotation_service.h"
#include "coordinator/annotations/annotation_store.h"
#include "coordinator/membership/coordinator_server.h"

namespace sandtable::sim {
namespace {

using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;

// Long enough that a recovery within half of it can only come from the dropped connection.
constexpr milliseconds kAckTimeout{6000};
constexpr double kRecoveryBound_s = 3.0;

struct Coordinator {
  std::unique_ptr<coordinator::AnnotationStore> store;
  std::unique_ptr<coordinator::AnnotationService> annotations;
  std::unique_ptr<coordinator::CoordinatorServer> server;
  std::atomic<bool> stop{false};
  std::thread thread;
  void Pause() {  // no more steps: requests wait unanswered, the sockets stay open
    stop = true;
    if (thread.joinable()) thread.join();
  }
  ~Coordinator() { Pause(); }
};

std::unique_ptr<Coordinator> StartCoordinator(const std::string& db, const std::string& endpoint) {
  auto c = std::make_unique<Coordinator>();
  Expected<std::unique_ptr<coordinator::AnnotationStore>> store =
      coordinator::AnnotationStore::Open(db);
  EXPECT_TRUE(store.ok()) << store.status().ToString();
  if (!store.ok()) return nullptr;
  c->store = std::move(*store);
  c->annotations = std::make_unique<coordinator::AnnotationService>(c->store.get());
  coordinator::CoordinatorOptions options;
  options.request_endpoint = endpoint;
  options.step_period = milliseconds(5);
  c->server = std::make_unique<coordinator::CoordinatorServer>(options);
  c->server->AddService(c->annotations.get());
  const Status started = c->server->Start();
  EXPECT_TRUE(started.ok()) << started.ToString();
  if (!started.ok()) return nullptr;
  c->thread = std::thread([raw = c.get()] { (void)raw->server->Run(raw->stop); });
  return c;
}

template <typename Pred>
bool WaitFor(Pred pred, milliseconds timeout) {
  const Clock::time_point until = Clock::now() + timeout;
  while (Clock::now() < until) {
    if (pred()) return true;
    std::this_thread::sleep_for(milliseconds(5));
  }
  return pred();
}

TEST(LabPainterTest, ACoordinatorThatDiesIsNoticedAtOnceAndNothingAcknowledgedIsLost) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("sandtable-lab-painter-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string db = (dir / "annotations.db").string();
  std::unique_ptr<Coordinator> first = StartCoordinator(db, "tcp://127.0.0.1:*");
  ASSERT_TRUE(first);
  const std::string endpoint = first->server->request_endpoint();
  LabPainterOptions options;
  options.requests_endpoint = endpoint;
  options.points_per_s = 200.0;
  options.ack_timeout = kAckTimeout;
  LabPainter painter(options);
  const Clock::time_point started = Clock::now();
  painter.Start();
  ASSERT_TRUE(
      WaitFor([&] { return painter.result().points_acknowledged >= 20; }, milliseconds(10000)));
  // Unanswered requests pile up (the window fills), then the coordinator's sockets close.
  first->Pause();
  std::this_thread::sleep_for(milliseconds(200));
  const double gone_s = std::chrono::duration<double>(Clock::now() - started).count();
  first.reset();
  std::unique_ptr<Coordinator> second = StartCoordinator(db, endpoint);
  ASSERT_TRUE(second);
  ASSERT_TRUE(WaitFor([&] { return painter.FirstAckAfter(gone_s) >= 0; }, kAckTimeout * 2));
  const double recovered_s = painter.FirstAckAfter(gone_s) - gone_s;
  EXPECT_LT(recovered_s, kRecoveryBound_s) << "the dropped connection, not the ack timeout";
  ASSERT_TRUE(WaitFor([&] { return painter.FirstAckAfter(gone_s + recovered_s + 0.2) >= 0; },
                      milliseconds(5000)))
      << "painting goes on";
  painter.Stop();
  const LabPainterResult result = painter.Verify(milliseconds(10000));
  EXPECT_TRUE(result.verified) << result.verify_error;
  EXPECT_GT(result.points_acknowledged, 20u);
  EXPECT_EQ(result.points_lost, 0u);
  EXPECT_GE(result.outages.size(), 1u);
  EXPECT_GE(result.strokes, 2) << "a new stroke after the outage";
  second.reset();
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace sandtable::sim
