#include "proto/convert.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace sandtable::proto {
namespace {

constexpr double kExact = 0.0;  // doubles travel bit-exact

TEST(ConvertTest, Rigid3RoundTripsExactly) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 20; ++i) {
    const Rigid3d table_from_projector(
        Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized(),
        Eigen::Vector3d(u(rng), u(rng), u(rng)));
    Expected<Rigid3d> back = FromWire(ToWire(table_from_projector));
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    EXPECT_LE((back->translation - table_from_projector.translation).norm(), kExact);
    EXPECT_LE(RotationAngleBetween_rad(*back, table_from_projector), 1e-12);
  }
}

TEST(ConvertTest, Rigid3RejectsBadRotation) {
  wire::Rigid3 missing;
  EXPECT_FALSE(FromWire(missing).ok());
  wire::Rigid3 scaled = ToWire(Rigid3d::Identity());
  scaled.mutable_rotation()->set_w(2.0);
  Expected<Rigid3d> r = FromWire(scaled);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("norm"), std::string::npos);
  wire::Rigid3 nan_t = ToWire(Rigid3d::Identity());
  nan_t.mutable_translation_m()->set_y(std::numeric_limits<double>::quiet_NaN());
  EXPECT_FALSE(FromWire(nan_t).ok());
}

TEST(ConvertTest, CameraModelRoundTripsAndValidates) {
  BrownDistortion d;
  d.k1 = -0.12;
  d.k2 = 0.03;
  d.p1 = 1e-4;
  d.p2 = -2e-4;
  d.k3 = 0.001;
  const CameraModel model(1280, 800, 1625.0, 1626.5, 639.5, 780.0, d);
  Expected<CameraModel> back = FromWire(ToWire(model));
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->width_px, model.width_px);
  EXPECT_EQ(back->height_px, model.height_px);
  EXPECT_LE(std::abs(back->fy_px - model.fy_px), kExact);
  EXPECT_LE(std::abs(back->cy_px - model.cy_px), kExact);
  EXPECT_LE(std::abs(back->distortion.k3 - model.distortion.k3), kExact);

  wire::CameraModel bad = ToWire(model);
  bad.set_fx_px(-1.0);
  EXPECT_FALSE(FromWire(bad).ok());
  bad = ToWire(model);
  bad.set_width_px(0xFFFFFFFFu);
  EXPECT_FALSE(FromWire(bad).ok());
}

TEST(ConvertTest, VectorsRejectNonFinite) {
  EXPECT_TRUE(FromWire(ToWire(Eigen::Vector3d(1, 2, 3))).ok());
  wire::Vector2 v;
  v.set_x(std::numeric_limits<double>::infinity());
  EXPECT_FALSE(FromWire(v).ok());
}

}  // namespace
}  // namespace sandtable::proto
