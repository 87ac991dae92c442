// PlanarFaces (common/scene/scene.h): one id per plane of a model, shared by its triangles
// whether they touch or not, and the same wherever the model is placed.
#include <cmath>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "common/scene/scene.h"

namespace sandtable {
namespace {

// Two boxes 3 cm apart: each has its own side walls, but their tops (one height), fronts and
// backs lie in shared planes.
Scene TwoBoxes() {
  Scene scene = MakeBoxMesh({-0.08, 0.0, 0.0}, {0.1, 0.1, 0.1}, 0.0, 0);
  scene.Append(MakeBoxMesh({0.08, 0.0, 0.0}, {0.1, 0.1, 0.1}, 0.0, 0));
  return scene;
}

bool Coplanar(const Scene& scene, int t, int u) {
  const Eigen::Vector3d nt = scene.FaceNormal(t), nu = scene.FaceNormal(u);
  const double dt = nt.dot(scene.positions_in_table_m[scene.triangles[t][0]].cast<double>());
  const double du = nu.dot(scene.positions_in_table_m[scene.triangles[u][0]].cast<double>());
  return nt.dot(nu) > 1.0 - 1e-9 && std::abs(dt - du) < 1e-6;
}

TEST(PlanarFacesTest, OneIdPerPlaneConnectedOrNot) {
  const Scene scene = TwoBoxes();
  const std::vector<int> face = PlanarFaces(scene);
  ASSERT_EQ(static_cast<int>(face.size()), scene.NumTriangles());
  std::set<int> ids;
  for (int t = 0; t < scene.NumTriangles(); ++t) {
    ASSERT_GE(face[t], 0);
    EXPECT_LE(face[t], t);  // the smallest triangle of its plane
    EXPECT_EQ(face[face[t]], face[t]);
    ids.insert(face[t]);
    for (int u = 0; u < t; ++u) {
      EXPECT_EQ(face[t] == face[u], Coplanar(scene, t, u)) << t << " " << u;
    }
  }
  // Shared planes: fewer ids than the two boxes have sides, more than one box has.
  EXPECT_GT(ids.size(), 6u);
  EXPECT_LT(ids.size(), 12u);
}

// Two coincident faces (a building duplicated, or two boxes sharing a wall's plane) show the
// same id, so the blend gives them one level instead of interleaving two.
TEST(PlanarFacesTest, CoincidentFacesAreOne) {
  Scene scene = MakeBoxMesh({0.0, 0.0, 0.0}, {0.1, 0.2, 0.1}, 0.3, 0);
  const int n = scene.NumTriangles();
  scene.Append(MakeBoxMesh({0.0, 0.0, 0.0}, {0.1, 0.2, 0.1}, 0.3, 0));
  const std::vector<int> face = PlanarFaces(scene);
  for (int t = 0; t < n; ++t) EXPECT_EQ(face[t], face[t + n]) << t;
}

TEST(PlanarFacesTest, TheSameIdsWhereverTheModelIsPlaced) {
  const Scene scene = TwoBoxes();
  const std::vector<int> face = PlanarFaces(scene);
  for (const Rigid3d& pose :
       {Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ())),
                {0.013, -0.021, 0.0}),
        Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.05, Eigen::Vector3d(1, 2, 3).normalized())),
                {0.2, 0.1, 0.003})}) {
    EXPECT_EQ(PlanarFaces(MovedScene(scene, pose)), face);
  }
}

TEST(PlanarFacesTest, ADegenerateTriangleHasNoPlane) {
  Scene scene = MakeRectangleMesh({1.0, 1.0}, 0);
  const int v = scene.NumVertices();
  scene.positions_in_table_m.push_back({0.0f, 0.0f, 0.0f});
  scene.positions_in_table_m.push_back({1.0f, 0.0f, 0.0f});
  scene.positions_in_table_m.push_back({2.0f, 0.0f, 0.0f});
  scene.triangles.push_back({v, v + 1, v + 2});
  scene.triangle_material.push_back(0);
  const std::vector<int> face = PlanarFaces(scene);
  EXPECT_EQ(face.back(), -1);
  EXPECT_EQ(face[0], 0);
  EXPECT_EQ(face[1], 0);  // the rectangle's two triangles: one plane
}

}  // namespace
}  // namespace sandtable
