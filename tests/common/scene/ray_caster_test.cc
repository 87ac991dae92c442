// The common ray caster (Embree) against an independent brute-force Moller-Trumbore in double,
// its batches against its single-ray calls, concurrent queries, and bad input.
#include "common/scene/ray_caster.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <thread>

#include "common/scene/procedural_scene.h"

namespace sandtable {
namespace {

// Brute force and caster both intersect the same (float) vertices in double.
constexpr double kDistanceTolerance_m = 1e-9;
constexpr double kUnitTolerance = 1e-12;
// Barycentrics rebuild the hit point to double rounding of metre-scale coordinates.
constexpr double kPointTolerance_m = 1e-9;

// Table plane (6 m square at z = 0) plus `boxes` random boxes on [-1, 1]^2.
std::shared_ptr<Scene> MakeBoxes(int boxes, uint32_t seed) {
  auto scene = std::make_shared<Scene>(MakeRectangleMesh({6.0, 6.0}, 0));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < boxes; ++i) {
    const Eigen::Vector3d centre(u(rng), u(rng), 0.0);
    const Eigen::Vector3d size(0.05, 0.05, 0.05 + 0.2 * (u(rng) + 1));
    scene->Append(MakeBoxMesh(centre, size, /*yaw_rad=*/u(rng), 0));
  }
  return scene;
}

std::unique_ptr<RayCaster> MakeCaster(std::shared_ptr<const Scene> scene) {
  Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(std::move(scene), "threads=1");
  EXPECT_TRUE(caster.ok()) << caster.status().ToString();
  return caster.ok() ? std::move(*caster) : nullptr;
}

struct BruteHit {
  double distance_m;
  int triangle;
};

// Closest hit by testing every triangle (Moller-Trumbore in double).
std::optional<BruteHit> BruteForce(const Scene& scene, const Eigen::Vector3d& o,
                                   const Eigen::Vector3d& direction, double near_m, double far_m) {
  const Eigen::Vector3d d = direction.normalized();
  std::optional<BruteHit> best;
  for (int t = 0; t < scene.NumTriangles(); ++t) {
    const Eigen::Vector3i& tri = scene.triangles[t];
    const Eigen::Vector3d p0 = scene.positions_in_table_m[tri[0]].cast<double>();
    const Eigen::Vector3d e1 = scene.positions_in_table_m[tri[1]].cast<double>() - p0;
    const Eigen::Vector3d e2 = scene.positions_in_table_m[tri[2]].cast<double>() - p0;
    const Eigen::Vector3d p = d.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) <= 1e-14 * e1.norm() * e2.norm()) continue;
    const Eigen::Vector3d s = o - p0;
    const double u = s.dot(p) / det;
    if (u < 0.0 || u > 1.0) continue;
    const Eigen::Vector3d q = s.cross(e1);
    const double v = d.dot(q) / det;
    if (v < 0.0 || u + v > 1.0) continue;
    const double distance = e2.dot(q) / det;
    if (distance < near_m || distance > far_m) continue;
    if (!best || distance < best->distance_m) best = BruteHit{distance, t};
  }
  return best;
}

// Random rays from above the boxes, downwards and sideways.
std::vector<Ray> RandomRays(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Ray> rays;
  for (int i = 0; i < n; ++i) {
    Ray ray;
    ray.origin_in_table_m = {u(rng), u(rng), 0.5 + 0.5 * u(rng)};
    ray.direction_in_table = {u(rng), u(rng), -1.0 + 0.5 * u(rng)};
    rays.push_back(ray);
  }
  return rays;
}

TEST(RayCasterTest, ClosestHitAgreesWithBruteForce) {
  const std::shared_ptr<Scene> scene = MakeBoxes(200, 4);
  const std::unique_ptr<RayCaster> caster = MakeCaster(scene);
  ASSERT_TRUE(caster);
  int hits = 0, box_hits = 0, front_hits = 0;
  for (const Ray& ray : RandomRays(2000, 9)) {
    const Eigen::Vector3d& o = ray.origin_in_table_m;
    const Eigen::Vector3d& d = ray.direction_in_table;
    const std::optional<RayHit> a = caster->Intersect(o, d);
    const std::optional<BruteHit> b = BruteForce(*scene, o, d, 0.0, kRayNoFar_m);
    ASSERT_EQ(a.has_value(), b.has_value()) << "ray from " << o.transpose();
    if (!a) continue;
    ++hits;
    box_hits += a->triangle >= 2;  // the table plane is triangles 0 and 1
    EXPECT_NEAR(a->distance_m, b->distance_m, kDistanceTolerance_m);
    const Eigen::Vector3d unit = d.normalized();
    EXPECT_NEAR((a->point_in_table_m - (o + a->distance_m * unit)).norm(), 0.0, kPointTolerance_m);
    EXPECT_NEAR(a->normal_in_table.norm(), 1.0, kUnitTolerance);
    EXPECT_LT(a->normal_in_table.dot(d), 0.0);  // faces the ray's origin
    // front_face: the counter-clockwise side (origins inside a box meet its faces' backs).
    EXPECT_EQ(a->front_face, scene->FaceNormal(a->triangle).dot(d) < 0.0);
    front_hits += a->front_face;
    // The barycentrics and the triangle's plane both hold the hit point.
    const Eigen::Vector3i& tri = scene->triangles[a->triangle];
    const Eigen::Vector3d rebuilt =
        (1 - a->u - a->v) * scene->positions_in_table_m[tri[0]].cast<double>() +
        a->u * scene->positions_in_table_m[tri[1]].cast<double>() +
        a->v * scene->positions_in_table_m[tri[2]].cast<double>();
    EXPECT_NEAR((rebuilt - a->point_in_table_m).norm(), 0.0, kPointTolerance_m);
    const Eigen::Hyperplane<double, 3> plane = caster->TrianglePlane(a->triangle);
    EXPECT_NEAR(plane.absDistance(a->point_in_table_m), 0.0, kPointTolerance_m);
    EXPECT_NEAR(std::abs(plane.normal().dot(a->normal_in_table)), 1.0, kUnitTolerance);
  }
  EXPECT_GT(hits, 1500);
  EXPECT_GT(box_hits, 200) << "the rays must exercise the boxes, not only the table";
  EXPECT_GT(front_hits, hits / 2);
}

TEST(RayCasterTest, NearAndFarBoundTheHit) {
  const std::shared_ptr<Scene> scene = MakeBoxes(0, 1);
  const std::unique_ptr<RayCaster> caster = MakeCaster(scene);
  ASSERT_TRUE(caster);
  const Eigen::Vector3d origin(0.1, 0.2, 1.0), down(0, 0, -2.0);  // table 1 m below
  ASSERT_TRUE(caster->Intersect(origin, down).has_value());
  EXPECT_NEAR(caster->Intersect(origin, down)->distance_m, 1.0, kDistanceTolerance_m);
  EXPECT_TRUE(caster->Intersect(origin, down, 0.0, 1.01).has_value());
  EXPECT_FALSE(caster->Intersect(origin, down, 0.0, 0.99).has_value());
  EXPECT_FALSE(caster->Intersect(origin, down, 1.01).has_value());
  EXPECT_FALSE(caster->Intersect(origin, -down).has_value());  // upwards: nothing
  // From below, the table is hit from its back: the normal still faces the ray's origin.
  const std::optional<RayHit> back = caster->Intersect({0.1, 0.2, -1.0}, -down);
  ASSERT_TRUE(back.has_value());
  EXPECT_FALSE(back->front_face);
  EXPECT_NEAR(back->normal_in_table.z(), -1.0, kUnitTolerance);
}

TEST(RayCasterTest, UncastableRaysMiss) {
  const std::unique_ptr<RayCaster> caster = MakeCaster(MakeBoxes(0, 1));
  ASSERT_TRUE(caster);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const Eigen::Vector3d origin(0, 0, 1), down(0, 0, -1);
  EXPECT_FALSE(caster->Intersect(origin, Eigen::Vector3d::Zero()).has_value());
  EXPECT_FALSE(caster->Intersect(origin, {nan, 0, -1}).has_value());
  EXPECT_FALSE(caster->Intersect(origin, {inf, 0, -1}).has_value());
  EXPECT_FALSE(caster->Intersect({nan, 0, 1}, down).has_value());
  EXPECT_FALSE(caster->Intersect(origin, down, 2.0, 1.0).has_value());  // empty range
  EXPECT_FALSE(caster->Intersect(origin, down, 0.0, nan).has_value());
  EXPECT_FALSE(caster->Occluded({nan, 0, 1}, {0, 0, -1}));
  EXPECT_FALSE(caster->Occluded({0, 0, 1}, {0, 0, 1}));  // no segment
  std::vector<std::optional<RayHit>> hits;
  caster->IntersectBatch({Ray{origin, Eigen::Vector3d::Zero()}, Ray{origin, down}}, &hits);
  ASSERT_EQ(hits.size(), 2u);
  EXPECT_FALSE(hits[0].has_value());
  EXPECT_TRUE(hits[1].has_value());
  caster->IntersectBatch({}, &hits);
  EXPECT_TRUE(hits.empty());
}

TEST(RayCasterTest, BatchesMatchSingleRays) {
  const std::shared_ptr<Scene> scene = MakeBoxes(100, 7);
  const std::unique_ptr<RayCaster> caster = MakeCaster(scene);
  ASSERT_TRUE(caster);
  const std::vector<Ray> rays = RandomRays(1000, 3);
  for (const bool coherent : {false, true}) {
    std::vector<std::optional<RayHit>> hits;
    caster->IntersectBatch(rays, &hits, coherent);
    ASSERT_EQ(hits.size(), rays.size());
    for (size_t i = 0; i < rays.size(); ++i) {
      const std::optional<RayHit> single = caster->Intersect(rays[i]);
      ASSERT_EQ(hits[i].has_value(), single.has_value()) << "ray " << i;
      if (!single) continue;
      EXPECT_EQ(hits[i]->triangle, single->triangle);
      EXPECT_EQ(hits[i]->distance_m, single->distance_m);
    }
  }
  // Shadow rays to one point (a projector centre above the scene).
  const Eigen::Vector3d centre(0.2, -0.1, 1.5);
  std::vector<Eigen::Vector3d> from;
  for (const Ray& ray : rays) {
    const std::optional<RayHit> hit = caster->Intersect(ray);
    if (hit) from.push_back(hit->point_in_table_m);
  }
  std::vector<uint8_t> occluded;
  caster->OccludedToPoint(from, centre, 5e-5, &occluded);
  ASSERT_EQ(occluded.size(), from.size());
  int shadowed = 0;
  for (size_t i = 0; i < from.size(); ++i) {
    EXPECT_EQ(occluded[i] != 0, caster->Occluded(from[i], centre, 5e-5)) << "point " << i;
    shadowed += occluded[i];
  }
  EXPECT_GT(shadowed, 0);
  EXPECT_LT(shadowed, static_cast<int>(from.size()));
}

TEST(RayCasterTest, OccludedAgreesWithBruteForceSegments) {
  const std::shared_ptr<Scene> scene = MakeBoxes(100, 11);
  const std::unique_ptr<RayCaster> caster = MakeCaster(scene);
  ASSERT_TRUE(caster);
  constexpr double kEpsilon_m = 1e-5;
  int blocked = 0;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector3d from(u(rng), u(rng), 0.01 + 0.3 * (u(rng) + 1));
    const Eigen::Vector3d to(u(rng), u(rng), 0.01 + 0.3 * (u(rng) + 1));
    const double length = (to - from).norm();
    const bool expected =
        BruteForce(*scene, from, to - from, kEpsilon_m, length - kEpsilon_m).has_value();
    EXPECT_EQ(caster->Occluded(from, to, kEpsilon_m), expected) << "segment " << i;
    blocked += expected;
  }
  EXPECT_GT(blocked, 100);
  EXPECT_LT(blocked, 900);
}

TEST(RayCasterTest, ConcurrentConstQueriesAgreeWithSerial) {
  const std::shared_ptr<Scene> scene = MakeBoxes(200, 2);
  Expected<std::unique_ptr<RayCaster>> created = RayCaster::Create(scene);  // Embree's threads
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const RayCaster& caster = **created;
  const std::vector<Ray> rays = RandomRays(4000, 8);
  std::vector<std::optional<RayHit>> serial;
  for (const Ray& ray : rays) serial.push_back(caster.Intersect(ray));
  constexpr int kThreads = 4;
  std::vector<std::vector<std::optional<RayHit>>> results(kThreads);
  std::vector<std::thread> pool;
  for (int t = 0; t < kThreads; ++t) {
    pool.emplace_back([&, t] {
      // Half the threads cast one by one, half in batches, all at once.
      if (t % 2 == 0) {
        for (const Ray& ray : rays) results[t].push_back(caster.Intersect(ray));
      } else {
        caster.IntersectBatch(rays, &results[t], /*coherent=*/false);
      }
    });
  }
  for (std::thread& thread : pool) thread.join();
  for (int t = 0; t < kThreads; ++t) {
    ASSERT_EQ(results[t].size(), rays.size());
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(results[t][i].has_value(), serial[i].has_value()) << "thread " << t << " ray " << i;
      if (serial[i]) {
        EXPECT_EQ(results[t][i]->distance_m, serial[i]->distance_m);
      }
    }
  }
}

TEST(RayCasterTest, BadScenesAreRejected) {
  EXPECT_EQ(RayCaster::Create(nullptr).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(RayCaster::Create(std::make_shared<Scene>()).status().code(),
            StatusCode::kInvalidArgument);
  auto out_of_range = std::make_shared<Scene>(MakeRectangleMesh({1.0, 1.0}, 0));
  out_of_range->triangles.push_back({0, 1, out_of_range->NumVertices()});
  Expected<std::unique_ptr<RayCaster>> bad_index = RayCaster::Create(out_of_range);
  EXPECT_EQ(bad_index.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad_index.status().message().find("triangle 2"), std::string::npos)
      << bad_index.status().ToString();
  auto not_finite = std::make_shared<Scene>(MakeRectangleMesh({1.0, 1.0}, 0));
  not_finite->positions_in_table_m[1].x() = std::numeric_limits<float>::infinity();
  EXPECT_EQ(RayCaster::Create(not_finite).status().code(), StatusCode::kInvalidArgument);
}

// Absurd but finite coordinates (1e19 m tripped Embree's assertions) and NaN are refused as a
// Status before Embree builds; rays from absurd origins are misses.
TEST(RayCasterTest, RefusesAbsurdCoordinates) {
  for (float bad : {1e19f, -2e4f, std::numeric_limits<float>::quiet_NaN()}) {
    auto scene = std::make_shared<Scene>(MakeRectangleMesh({1.0, 1.0}, 0));
    scene->positions_in_table_m[2].y() = bad;
    Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(scene, "threads=1");
    ASSERT_FALSE(caster.ok()) << bad;
    EXPECT_EQ(caster.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(caster.status().message().find("vertex 2"), std::string::npos)
        << caster.status().ToString();
    if (std::isfinite(bad)) {
      EXPECT_NE(caster.status().message().find("kMaxSceneCoordinate_m"), std::string::npos)
          << caster.status().ToString();
    }
  }
  auto at_limit = std::make_shared<Scene>(MakeRectangleMesh({1.0, 1.0}, 0));
  at_limit->positions_in_table_m[0].x() = static_cast<float>(kMaxSceneCoordinate_m);
  EXPECT_TRUE(RayCaster::Create(at_limit, "threads=1").ok());
  const std::unique_ptr<RayCaster> caster =
      MakeCaster(std::make_shared<Scene>(MakeRectangleMesh({1.0, 1.0}, 0)));
  const Eigen::Vector3d down(0, 0, -1);
  EXPECT_FALSE(caster->Intersect(Eigen::Vector3d(0, 0, 1e19), down).has_value());
  EXPECT_FALSE(caster->Intersect(Eigen::Vector3d(0, 0, 2 * kMaxRayOrigin_m), down).has_value());
  EXPECT_TRUE(caster->Intersect(Eigen::Vector3d(0, 0, 1), down).has_value());
}

TEST(RayCasterTest, DegenerateTrianglesNeverHit) {
  auto scene = std::make_shared<Scene>();
  scene->positions_in_table_m = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};  // collinear
  scene->triangles = {{0, 1, 2}};
  const std::unique_ptr<RayCaster> caster = MakeCaster(scene);
  ASSERT_TRUE(caster);
  EXPECT_FALSE(caster->Intersect({0.5, 0, 1}, {0, 0, -1}).has_value());
  EXPECT_FALSE(caster->Intersect({0.5, -1, 0}, {0, 1, 0}).has_value());  // along its line
}

}  // namespace
}  // namespace sandtable
