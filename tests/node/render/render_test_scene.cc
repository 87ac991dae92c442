#include "tests/node/render/render_test_scene.h"

#include <Eigen/Geometry>

#include "common/scene/procedural_scene.h"

namespace sandtable::testing {

Scene RenderTestScene() {
  Scene scene;
  scene.materials.resize(3);
  scene.materials[0].name = "table";
  scene.materials[0].base_color_texture = 0;
  scene.materials[1].name = "red";
  scene.materials[1].base_color_factor = Eigen::Vector4d(0.8, 0.1, 0.05, 1.0);
  scene.materials[2].name = "grey";
  scene.materials[2].base_color_factor = Eigen::Vector4d(0.6, 0.6, 0.6, 1.0);
  // Checker imagery with a colour gradient, 64 x 64 texels over the table.
  Texture texture;
  texture.width_px = texture.height_px = 64;
  texture.rgba.resize(64 * 64 * 4);
  for (int y = 0; y < 64; ++y) {
    for (int x = 0; x < 64; ++x) {
      const bool dark = ((x / 8) + (y / 8)) % 2 == 0;
      uint8_t* p = &texture.rgba[(y * 64 + x) * 4];
      p[0] = static_cast<uint8_t>(dark ? 40 : 200 + x / 2);
      p[1] = static_cast<uint8_t>(dark ? 60 : 180);
      p[2] = static_cast<uint8_t>(dark ? 30 + y : 120);
      p[3] = 255;
    }
  }
  texture.repeat_s = texture.repeat_t = false;
  scene.textures.push_back(texture);
  // The table: a rectangle at z = 0 with texture coordinates over [0, 1]^2.
  const float hx = 0.6f, hy = 0.4f;
  scene.positions_in_table_m = {{-hx, -hy, 0}, {hx, -hy, 0}, {hx, hy, 0}, {-hx, hy, 0}};
  scene.texcoords = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
  scene.triangles = {{0, 1, 2}, {0, 2, 3}};
  scene.triangle_material = {0, 0};
  Scene box =
      MakeBoxMesh(Eigen::Vector3d(0.1, 0.05, 0.0), Eigen::Vector3d(0.12, 0.1, 0.15), 0.3, 1);
  Scene tower =
      MakeBoxMesh(Eigen::Vector3d(-0.25, -0.1, 0.0), Eigen::Vector3d(0.06, 0.06, 0.3), 0.0, 2);
  box.texcoords.assign(box.positions_in_table_m.size(), Eigen::Vector2f::Zero());
  tower.texcoords.assign(tower.positions_in_table_m.size(), Eigen::Vector2f::Zero());
  scene.Append(box);
  scene.Append(tower);
  return scene;
}

CameraModel RenderTestProjector(int width_px, int height_px, bool distortion) {
  const double scale = width_px / 320.0;
  // Lens shift: the principal point below the image centre.
  CameraModel model(width_px, height_px, 330.0 * scale, 331.0 * scale, 0.506 * width_px,
                    0.65 * height_px);
  if (distortion) {
    model.distortion.k1 = -0.08;
    model.distortion.k2 = 0.03;
    model.distortion.p1 = 0.002;
    model.distortion.p2 = -0.001;
  }
  return model;
}

Rigid3d RenderTestProjectorFromTable() {
  // Projector at (0, -0.9, 1.3) m looking at (0, -0.05, 0); image x along table +x.
  const Eigen::Vector3d eye(0.0, -0.9, 1.3), target(0.0, -0.05, 0.0);
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d table_from_projector_r;
  table_from_projector_r.col(0) = x;
  table_from_projector_r.col(1) = y;
  table_from_projector_r.col(2) = z;
  return Rigid3d(table_from_projector_r, eye).Inverse();
}

}  // namespace sandtable::testing
