#include "common/scene/gltf_loader.h"

#include <string>

#include <gtest/gtest.h>

namespace sandtable::sim {
namespace {

const std::string kData = "../shared/data/gltf/";
constexpr double kTolerance_m = 1e-6;
constexpr double kAlbedoTolerance = 1e-6;  // the file stores 0.8 as float

TEST(GltfLoader, BoxEmbeddedWithRootMatrix) {
  GltfLoadReport report;
  Expected<Scene> scene = LoadGltfScene(kData + "khronos/Box/glTF-Embedded/Box.gltf", {}, &report);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  EXPECT_EQ(scene->NumVertices(), 24);
  EXPECT_EQ(scene->NumTriangles(), 12);
  // Unit cube centred at the origin: the root matrix and the frame change keep it a unit cube.
  const Eigen::AlignedBox3d box = scene->Bounds();
  EXPECT_NEAR(box.min().x(), -0.5, kTolerance_m);
  EXPECT_NEAR(box.max().z(), 0.5, kTolerance_m);
  ASSERT_EQ(scene->materials.size(), 1u);
  EXPECT_NEAR(scene->materials[0].base_color_factor.x(), 0.8, kAlbedoTolerance);
  EXPECT_NEAR(scene->AlbedoRgbAt(0, 0.2, 0.2).x(), 0.8, kAlbedoTolerance);
  EXPECT_NEAR(scene->AlbedoRgbAt(0, 0.2, 0.2).y(), 0.0, kAlbedoTolerance);
  // Outward winding: every face normal points away from the centre.
  for (int t = 0; t < scene->NumTriangles(); ++t) {
    const Eigen::Vector3d centroid =
        (scene->positions_in_table_m[scene->triangles[t][0]].cast<double>() +
         scene->positions_in_table_m[scene->triangles[t][1]].cast<double>() +
         scene->positions_in_table_m[scene->triangles[t][2]].cast<double>()) /
        3.0;
    EXPECT_GT(scene->FaceNormal(t).dot(centroid), 0.0) << "triangle " << t;
  }
}

TEST(GltfLoader, BoxTexturedKeepsTexture) {
  Expected<Scene> scene =
      LoadGltfScene(kData + "khronos/BoxTextured/glTF-Embedded/BoxTextured.gltf");
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  EXPECT_EQ(scene->NumVertices(), 24);
  EXPECT_EQ(scene->NumTriangles(), 12);
  ASSERT_EQ(scene->textures.size(), 1u);
  EXPECT_EQ(scene->textures[0].width_px, 211);
  EXPECT_EQ(scene->textures[0].height_px, 211);
  ASSERT_EQ(scene->texcoords.size(), 24u);
  // The albedo varies over the faces (the logo), within [0, 1].
  double min_albedo = 1.0, max_albedo = 0.0;
  for (int t = 0; t < scene->NumTriangles(); ++t) {
    for (double u = 0.05; u < 0.9; u += 0.1) {
      const double a = scene->AlbedoAt(t, u, 0.05);
      min_albedo = std::min(min_albedo, a);
      max_albedo = std::max(max_albedo, a);
    }
  }
  EXPECT_GE(min_albedo, 0.0);
  EXPECT_LE(max_albedo, 1.0);
  EXPECT_GT(max_albedo - min_albedo, 0.1);
}

TEST(GltfLoader, CubeWithExternalBuffer) {
  Expected<Scene> scene = LoadGltfScene(kData + "tinygltf/Cube/Cube.gltf");
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  EXPECT_EQ(scene->NumVertices(), 36);
  EXPECT_EQ(scene->NumTriangles(), 12);
  const Eigen::AlignedBox3d box = scene->Bounds();
  EXPECT_NEAR(box.max().x(), 1.0, 1e-5);
  EXPECT_NEAR(box.min().y(), -1.0, 1e-5);
}

TEST(GltfLoader, BinaryGlb) {
  Expected<Scene> scene = LoadGltfScene(kData + "tinygltf/box01.glb");
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  EXPECT_EQ(scene->NumVertices(), 32);
  EXPECT_EQ(scene->NumTriangles(), 12);
}

TEST(GltfLoader, FrameChangeGltfYUpToTableZUp) {
  const Eigen::Matrix3d r = TableFromGltfRotation();
  EXPECT_TRUE(r.isApprox(Eigen::Matrix3d(r.transpose().inverse())));
  EXPECT_NEAR(r.determinant(), 1.0, 1e-15);
  const Eigen::Vector3d up_in_gltf(0, 1, 0);
  EXPECT_TRUE((r * up_in_gltf).isApprox(Eigen::Vector3d(0, 0, 1)));
  const Eigen::Vector3d toward_viewer_in_gltf(0, 0, 1);  // glTF +z -> table -y
  EXPECT_TRUE((r * toward_viewer_in_gltf).isApprox(Eigen::Vector3d(0, -1, 0)));
}

TEST(GltfLoader, ScaleOption) {
  GltfLoadOptions options;
  options.scale_m_per_unit = 0.01;
  Expected<Scene> scene = LoadGltfScene(kData + "tinygltf/box01.glb", options);
  ASSERT_TRUE(scene.ok());
  EXPECT_NEAR(scene->Bounds().sizes().x(), 0.01, kTolerance_m);
  options.scale_m_per_unit = -1;
  EXPECT_FALSE(LoadGltfScene(kData + "tinygltf/box01.glb", options).ok());
}

class BadGltf : public testing::TestWithParam<std::string> {};

TEST_P(BadGltf, FailsWithClearError) {
  Expected<Scene> scene = LoadGltfScene(kData + "tinygltf/BoundsChecking/" + GetParam());
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.status().message().find(GetParam()), std::string::npos)
      << "message must name the file: " << scene.status().message();
  EXPECT_GT(scene.status().message().size(), GetParam().size() + 10);
}

INSTANTIATE_TEST_SUITE_P(BoundsChecking, BadGltf,
                         testing::Values("integer-out-of-bounds.gltf", "invalid-buffer-index.gltf",
                                         "invalid-buffer-view-index.gltf",
                                         "invalid-primitive-indices.gltf"));

TEST(GltfLoader, MissingFileIsAnError) {
  Expected<Scene> scene = LoadGltfScene(kData + "does-not-exist.gltf");
  EXPECT_FALSE(scene.ok());
}

}  // namespace
}  // namespace sandtable::sim
