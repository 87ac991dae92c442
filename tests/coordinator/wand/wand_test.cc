#include "coordinator/wand/wand.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <random>

#include "coordinator/tracker/replay_source.h"

namespace sandtable::coordinator {
namespace {

constexpr double kHitTolerance_m = 1e-9;
constexpr double kNormalTolerance = 1e-12;
const char* kTraj = "../shared/data/polhemus-hand/pick_and_place/user1_cup0.traj";

// Table plane (6 m square at z = 0) plus one building.
const Eigen::Vector3d kBoxLo(0.2, 0.1, 0.0), kBoxHi(0.5, 0.4, 0.3);
RayCaster MakeScene(int extra_boxes = 0, uint32_t seed = 1) {
  std::vector<Eigen::Vector3d> p = {{-3, -3, 0}, {3, -3, 0}, {3, 3, 0}, {-3, 3, 0}};
  std::vector<Eigen::Vector3i> t = {{0, 1, 2}, {0, 2, 3}};
  AppendBox(kBoxLo, kBoxHi, &p, &t);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < extra_boxes; ++i) {
    const Eigen::Vector3d lo(u(rng), u(rng), 0.0);
    AppendBox(lo, lo + Eigen::Vector3d(0.05, 0.05, 0.05 + 0.2 * (u(rng) + 1)), &p, &t);
  }
  return RayCaster(p, t);
}

// Independent closest hit of the plane z = 0 and the box (slabs), or nullopt.
std::optional<double> ExpectedDistance(const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  std::optional<double> best;
  if (d.z() != 0.0) {
    const double t = -o.z() / d.z();
    const Eigen::Vector3d p = o + t * d;
    if (t > 0 && std::abs(p.x()) <= 3 && std::abs(p.y()) <= 3) best = t;
  }
  double t0 = 0.0, t1 = 1e9;
  bool box = true;
  for (int a = 0; a < 3 && box; ++a) {
    double ta = (kBoxLo[a] - o[a]) / d[a], tb = (kBoxHi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    box = t0 <= t1;
  }
  if (box && t0 > 0 && (!best || t0 < *best)) best = t0;
  return best;
}

TEST(RayCasterTest, BvhAgreesWithBruteForce) {
  const RayCaster scene = MakeScene(200, 4);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int hits = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d o(u(rng), u(rng), 0.5 + 0.5 * u(rng));
    const Eigen::Vector3d d(u(rng), u(rng), -1.0 + 0.5 * u(rng));
    const std::optional<RayHit> a = scene.Cast(o, d), b = scene.CastBruteForce(o, d);
    ASSERT_EQ(a.has_value(), b.has_value()) << "ray " << i;
    if (!a) continue;
    ++hits;
    EXPECT_NEAR(a->distance_m, b->distance_m, kHitTolerance_m);
    EXPECT_LT(a->normal_in_table.dot(d), 0.0);  // faces the wand
  }
  EXPECT_GT(hits, 1500);
}

TEST(WandTest, FastrakTrajectoryDrivesTheCursorThroughReplay) {
  if (!std::filesystem::exists(kTraj)) GTEST_SKIP() << kTraj << " not present";
  Expected<std::vector<TrackerSample>> samples = LoadFastrakTraj(kTraj);
  ASSERT_TRUE(samples.ok()) << samples.status().ToString();
  // The dataset's base is ~1.1-3 m from the hands: put the table 1 m below its origin and
  // centre the workspace (an assumed calibration; the real one comes from FitTableFromTracker).
  const Rigid3d table_from_tracker(Eigen::Quaterniond::Identity(),
                                   Eigen::Vector3d(-0.7, -0.35, -1.0));
  WandOptions options;
  // In this recording the wrist sensor's -z axis points down at the table (all 290 rays hit).
  options.ray_in_sensor = -Eigen::Vector3d::UnitZ();
  const RayCaster scene = MakeScene();
  ReplaySource replay(kTraj, *samples, /*rate_scale=*/1.0);
  const TrackerClock::time_point t0{};
  std::vector<TrackerSample> due;
  int cursors = 0, hits = 0, box_hits = 0;
  // Drive the replay at the tracker rate: one poll per 10 ms of clock, one cursor per sample.
  for (int tick = 0; replay.state() != TrackerState::kEnded; ++tick) {
    due.clear();
    ASSERT_TRUE(replay.Poll(t0 + std::chrono::milliseconds(10 * tick), &due).ok());
    ASSERT_LE(due.size(), 2u);  // at most one sample late at each tick: the tracker rate
    for (const TrackerSample& s : due) {
      const CursorState cursor = ComputeCursor(s, table_from_tracker, scene, options);
      const wire::Cursor event = ToWire(cursor, 10'000'000LL * tick);
      ++cursors;
      const std::optional<double> expected =
          ExpectedDistance(cursor.tip_in_table_m, cursor.direction_in_table);
      ASSERT_EQ(cursor.hit.has_value(), expected.has_value()) << "sample " << cursors;
      EXPECT_EQ(event.hit(), cursor.hit.has_value());
      if (!cursor.hit) continue;
      ++hits;
      EXPECT_NEAR(cursor.hit->distance_m, *expected, kHitTolerance_m);
      const Eigen::Vector3d n = cursor.hit->normal_in_table;
      EXPECT_NEAR(n.norm(), 1.0, kNormalTolerance);
      if (cursor.hit->point_in_table_m.z() > kHitTolerance_m) ++box_hits;
      EXPECT_NEAR(event.hit_in_table_m().x(), cursor.hit->point_in_table_m.x(), kHitTolerance_m);
    }
  }
  EXPECT_EQ(cursors, static_cast<int>(samples->size()));
  std::cout << cursors << " cursor events, " << hits << " on the scene, " << box_hits
            << " on the building\n";
  EXPECT_EQ(hits, cursors);
}

}  // namespace
}  // namespace sandtable::coordinator
