// The blend's wire form (node/blend/blend_service.h): a distance field survives BlendShare
// exactly, and a share that does not describe a field (a grid that does not span its projector,
// values that are not finite, a model that does not check) is refused with a message.
#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "node/blend/blend_service.h"

namespace sandtable::node {
namespace {

DistanceField MakeField() {
  DistanceField f;
  f.unit = 7;
  f.projector = CameraModel::FromThrowRatio(320, 200, 1.27);
  f.projector_from_table = Rigid3d(Eigen::Quaterniond(0.9, 0.1, -0.2, 0.3), {0.1, -0.2, 1.5});
  f.step_px = 8;
  f.cols = DistanceField::PointsAlong(320, 8);
  f.rows = DistanceField::PointsAlong(200, 8);
  f.distance_m.resize(static_cast<size_t>(f.cols) * f.rows);
  for (size_t i = 0; i < f.distance_m.size(); ++i) f.distance_m[i] = 0.001f * (i % 97) - 0.01f;
  return f;
}

TEST(BlendShareTest, AFieldSurvivesTheWire) {
  const DistanceField field = MakeField();
  ASSERT_TRUE(field.Check().ok()) << field.Check().ToString();
  const wire::BlendShare share = ShareFromField(field, 42);
  EXPECT_EQ(share.calibration_round(), 42u);
  Expected<DistanceField> back = FieldFromShare(share);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->unit, field.unit);
  EXPECT_EQ(back->cols, field.cols);
  EXPECT_EQ(back->rows, field.rows);
  EXPECT_EQ(back->distance_m, field.distance_m);
  EXPECT_EQ(back->projector.fx_px, field.projector.fx_px);
  EXPECT_TRUE(
      back->projector_from_table.translation.isApprox(field.projector_from_table.translation));
  // The bilinear lookup: the grid's outer points lie on the image's edges.
  EXPECT_FLOAT_EQ(back->DistanceAtPixel(back->GridPixel(3, 2)),
                  std::max(0.0f, field.distance_m[2 * field.cols + 3]));
  EXPECT_EQ(back->DistanceAtPixel({-5.0, 10.0}), 0.0f);
}

// A share received again (a neighbour asked again) is recognised, so the node does not look it
// up again; any change of the field, its projector or its pose is not.
TEST(BlendShareTest, AFieldReceivedAgainIsTheSameAndAChangedOneIsNot) {
  const wire::BlendShare share = ShareFromField(MakeField(), 3);
  Expected<DistanceField> first = FieldFromShare(share), again = FieldFromShare(share);
  ASSERT_TRUE(first.ok() && again.ok());
  EXPECT_TRUE(SameField(*first, *again));
  DistanceField changed = *again;
  changed.distance_m[10] += 1e-6f;
  EXPECT_FALSE(SameField(*first, changed));
  changed = *again;
  changed.projector_from_table.translation.x() += 1e-9;
  EXPECT_FALSE(SameField(*first, changed));
  changed = *again;
  changed.projector.distortion.k1 = 0.01;
  EXPECT_FALSE(SameField(*first, changed));
  changed = *again;
  changed.unit = 8;
  EXPECT_FALSE(SameField(*first, changed));
}

TEST(BlendShareTest, RefusesSharesThatAreNotAField) {
  const wire::BlendShare good = ShareFromField(MakeField(), 1);
  {
    wire::BlendShare bad = good;
    bad.mutable_distance_m()->RemoveLast();
    Expected<DistanceField> f = FieldFromShare(bad);
    ASSERT_FALSE(f.ok());
    EXPECT_NE(f.status().message().find("distances for a"), std::string::npos)
        << f.status().message();
  }
  {
    wire::BlendShare bad = good;
    bad.set_distance_m(5, std::numeric_limits<float>::quiet_NaN());
    EXPECT_FALSE(FieldFromShare(bad).ok());
  }
  {
    wire::BlendShare bad = good;
    bad.set_cols(good.cols() + 1);
    bad.mutable_distance_m()->Resize(static_cast<int>((good.cols() + 1) * good.rows()), 0.0f);
    Expected<DistanceField> f = FieldFromShare(bad);
    ASSERT_FALSE(f.ok());
    EXPECT_NE(f.status().message().find("does not span"), std::string::npos)
        << f.status().message();
  }
  {
    wire::BlendShare bad = good;
    bad.mutable_projector_model()->set_fx_px(-1.0);
    EXPECT_FALSE(FieldFromShare(bad).ok());
  }
  {
    wire::BlendShare bad = good;
    bad.set_step_px(1000);
    EXPECT_FALSE(FieldFromShare(bad).ok());
  }
}

}  // namespace
}  // namespace sandtable::node
