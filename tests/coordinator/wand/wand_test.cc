#include "coordinator/wand/wand.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <memory>

#include "common/scene/procedural_scene.h"
#include "coordinator/tracker/replay_source.h"

namespace sandtable::coordinator {
namespace {

constexpr double kHitTolerance_m = 1e-9;
constexpr double kNormalTolerance = 1e-12;
const char* kTraj = "../shared/data/polhemus-hand/pick_and_place/user1_cup0.traj";

// Table plane (6 m square at z = 0) plus one building. The corners are dyadic, so the scene's
// float vertices hold them exactly and hit distances are exact to double rounding (the
// caster refines Embree's float hits in double).
const Eigen::Vector3d kBoxLo(0.25, 0.125, 0.0), kBoxHi(0.5, 0.375, 0.3125);
std::unique_ptr<RayCaster> MakeScene() {
  auto scene = std::make_shared<Scene>(MakeRectangleMesh({6.0, 6.0}, 0));
  scene->Append(MakeBoxMesh({0.5 * (kBoxLo.x() + kBoxHi.x()), 0.5 * (kBoxLo.y() + kBoxHi.y()), 0},
                            kBoxHi - kBoxLo, 0.0, 0));
  Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(std::move(scene));
  EXPECT_TRUE(caster.ok()) << caster.status().ToString();
  return caster.ok() ? std::move(*caster) : nullptr;
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

TEST(WandTest, NoSceneNeverHits) {
  TrackerSample sample;
  sample.tracker_from_sensor = Rigid3d(Eigen::Quaterniond::Identity(), {0, 0, 1});
  WandOptions options;
  options.ray_in_sensor = -Eigen::Vector3d::UnitZ();
  const CursorState cursor = ComputeCursor(sample, Rigid3d::Identity(), nullptr, options);
  EXPECT_FALSE(cursor.hit.has_value());
  EXPECT_NEAR(cursor.tip_in_table_m.z(), 1.0, kHitTolerance_m);
  const std::unique_ptr<RayCaster> scene = MakeScene();
  ASSERT_TRUE(scene);
  const CursorState hit = ComputeCursor(sample, Rigid3d::Identity(), scene.get(), options);
  ASSERT_TRUE(hit.hit.has_value());
  EXPECT_NEAR(hit.hit->distance_m, 1.0, kHitTolerance_m);
  EXPECT_NEAR(hit.hit->normal_in_table.z(), 1.0, kNormalTolerance);
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
  const std::unique_ptr<RayCaster> scene = MakeScene();
  ASSERT_TRUE(scene);
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
      const CursorState cursor = ComputeCursor(s, table_from_tracker, scene.get(), options);
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
