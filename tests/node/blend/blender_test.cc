// Blender: the composition without one neighbour (what a node prepares for that neighbour
// leaving, docs/blend.md "Prepared masks") is, bit for bit, the composition after the neighbour
// is removed, face levels included. sandtable-3 at its true poses: unit 0 and its two overlapping
// neighbours.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <memory>

#include "common/scene/procedural_scene.h"
#include "node/blend/blend_field.h"
#include "sim/site/site_presets.h"

namespace sandtable::node {
namespace {

bool Identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && a.isContinuous() && b.isContinuous() &&
         std::memcmp(a.data, b.data, a.total() * a.elemSize()) == 0;
}

TEST(BlenderTest, WithoutANeighbourIsTheBlendAfterItIsRemoved) {
  Expected<sim::Site> site = sim::MakeSitePreset("sandtable-3");
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  ProceduralSceneOptions scene_options;
  scene_options.seed = 1;
  auto scene = std::make_shared<const Scene>(MakeProceduralScene(scene_options)->scene);
  Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(scene);
  ASSERT_TRUE(caster.ok()) << caster.status().ToString();
  BlendOptions options;
  std::map<NodeId, DistanceField> fields;
  for (const sim::UnitSpec& unit : site->units) {
    fields[unit.id] =
        ComputeDistanceField(unit.id, unit.projector.model,
                             unit.projector.table_from_projector.Inverse(), **caster, options);
  }
  const sim::UnitSpec& own = site->units.at(0);
  const ProjectorSurface surface =
      CastProjectorSurface(own.projector.model, own.projector.table_from_projector.Inverse(),
                           **caster, options, PlanarFaces(*scene));
  Blender all(surface, fields.at(0), caster->get(), options);
  for (const auto& [id, field] : fields) {
    if (id != 0) all.SetNeighbour(field);
  }
  ASSERT_EQ(all.neighbours().size(), 2u);
  const double level = all.LevelBound();
  ASSERT_TRUE(std::isfinite(level) && level > 0);
  // Black levels as measured, one per unit (the lift's terms).
  const std::map<NodeId, double> black = {{1, 0.0021}, {2, 0.0019}};
  constexpr double kOwnBlack = 0.002, kMaxLift = 0.05;
  const double target = all.BlackPeak(kOwnBlack, black) * 1.5;
  // Face levels off the wire name faces this model does not have: left out, no harm.
  EXPECT_TRUE(
      Identical(all.Factor(level, options.fill_limit, kInvalidNodeId,
                           {{std::numeric_limits<int32_t>::max(), 0.5 * level}, {-3, 0.5 * level}}),
                all.Factor(level)));
  for (NodeId left : all.neighbours()) {
    SCOPED_TRACE("without unit " + std::to_string(left));
    Blender removed(surface, fields.at(0), caster->get(), options);
    for (const auto& [id, field] : fields) {
      if (id != 0) removed.SetNeighbour(field);
    }
    ASSERT_TRUE(removed.RemoveNeighbour(left));
    const cv::Mat prepared = all.Factor(level, options.fill_limit, left);
    EXPECT_TRUE(Identical(prepared, removed.Factor(level)));
    EXPECT_FALSE(Identical(prepared, all.Factor(level))) << "the neighbour shared this blend";
    EXPECT_TRUE(Identical(all.Alpha(left), removed.Alpha()));
    // The faces' levels (walls met past the correction limit) and the mask at them.
    const FaceLevels faces = all.FaceLevelBounds(level, options.fill_limit, left);
    EXPECT_EQ(faces, removed.FaceLevelBounds(level, options.fill_limit));
    EXPECT_FALSE(faces.empty());
    EXPECT_TRUE(Identical(all.Factor(level, options.fill_limit, left, faces),
                          removed.Factor(level, options.fill_limit, kInvalidNodeId, faces)));
    EXPECT_EQ(all.BlackPeak(kOwnBlack, black, left), removed.BlackPeak(kOwnBlack, black));
    EXPECT_TRUE(Identical(all.Lift(target, kOwnBlack, black, kMaxLift, left),
                          removed.Lift(target, kOwnBlack, black, kMaxLift)));
  }
}

}  // namespace
}  // namespace sandtable::node
