// The blend's wire form (node/blend/blend_service.h): a distance field survives BlendShare
// exactly, and a share that does not describe a field (a grid that does not span its projector,
// values that are not finite, a model that does not check) is refused with a message; so are
// face levels that are not levels.
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <utility>

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

// Face levels (Blender::FaceLevelBounds) on the wire: absent (the sender has not composed),
// present and empty (no face below the site's level), or a list; a face id below 0, a level
// that is not finite and positive, or a face listed twice is refused.
TEST(BlendShareTest, FaceLevelsSurviveTheWireAndBadOnesAreRefused) {
  wire::BlendShare share = ShareFromField(MakeField(), 1);
  Expected<std::optional<FaceLevels>> none = FaceLevelsFromShare(share);
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
  share.set_has_face_levels(true);
  Expected<std::optional<FaceLevels>> empty = FaceLevelsFromShare(share);
  ASSERT_TRUE(empty.ok() && empty->has_value());
  EXPECT_TRUE((*empty)->empty());
  for (auto [face, level] : {std::pair<int, double>{4, 0.05}, {130, 0.0123}}) {
    wire::FaceLevel* f = share.add_face_levels();
    f->set_face(face);
    f->set_level_per_m2(level);
  }
  Expected<std::optional<FaceLevels>> two = FaceLevelsFromShare(share);
  ASSERT_TRUE(two.ok()) << two.status().ToString();
  ASSERT_TRUE(two->has_value());
  EXPECT_EQ(**two, (FaceLevels{{4, 0.05}, {130, 0.0123}}));
  for (auto [face, level] : {std::pair<int, double>{-1, 0.05},
                             {5, 0.0},
                             {5, -1.0},
                             {5, std::numeric_limits<double>::infinity()},
                             {5, std::numeric_limits<double>::quiet_NaN()},
                             {4, 0.01}}) {
    wire::BlendShare bad = share;
    wire::FaceLevel* f = bad.add_face_levels();
    f->set_face(face);
    f->set_level_per_m2(level);
    Expected<std::optional<FaceLevels>> refused = FaceLevelsFromShare(bad);
    ASSERT_FALSE(refused.ok()) << face << " " << level;
    EXPECT_NE(refused.status().message().find("face"), std::string::npos);
  }
  wire::BlendShare unflagged = share;
  unflagged.set_has_face_levels(false);
  EXPECT_FALSE(FaceLevelsFromShare(unflagged).ok());
}

// The level a face shows: the lowest any node holds for it, a node that left aside.
TEST(BlendShareTest, AFaceShowsTheLowestLevelHeld) {
  const std::map<NodeId, FaceLevels> held = {{1, {{4, 0.05}, {9, 0.02}}}, {2, {{4, 0.03}}}};
  EXPECT_EQ(LowestFaceLevels(held, {{9, 0.04}, {12, 0.1}}),
            (FaceLevels{{4, 0.03}, {9, 0.02}, {12, 0.1}}));
  EXPECT_EQ(LowestFaceLevels(held, {{9, 0.04}}, 1), (FaceLevels{{4, 0.03}, {9, 0.04}}));
  EXPECT_TRUE(LowestFaceLevels({}, {}).empty());
}

}  // namespace
}  // namespace sandtable::node
