// The renderer's frames through the simulated world (sim/transport/world.h): sandtable-3 at its
// true poses, every unit rendering a wand stroke painted on the table at a point some projectors
// light and at least one does not (a building stands between it and the point). Seen from above
// with one projector lit at a time, the stroke must appear in every projector that lights the
// point and in none that is occluded. (The grid's registration across projectors through the
// world is the lab's measurement: sim/lab/render_metrics.h.)
#include <cmath>
#include <iostream>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "node/render/gl_context.h"
#include "node/render/renderer.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"

namespace sandtable::node {
namespace {

// A lit stroke against its surroundings in a projector's top view: ratio of luminance.
constexpr double kShownContrast = 3.0;
// An occluded projector adds at most this share to the ambient level at the stroke.
constexpr double kHiddenContrast = 1.2;
// The occluder stands at least this far from the point along the projector's ray, beyond the
// overlay's lift (overlay_geometry.h).
constexpr double kOccluderDistance_m = 0.08;

struct Site3 {
  sim::Site site;
  Scene scene;
  std::unique_ptr<sim::World> world;
};

Site3 MakeSite() {
  Site3 s;
  s.site = *sim::MakeSitePreset("sandtable-3");
  ProceduralSceneOptions options;
  options.seed = 1;
  s.scene = MakeProceduralScene(options)->scene;
  Expected<std::unique_ptr<sim::World>> world = sim::World::Create(s.site, s.scene);
  EXPECT_TRUE(world.ok()) << world.status().ToString();
  if (world.ok()) s.world = std::move(*world);
  return s;
}

// Each unit's frame of `content`, rendered from its true pose with `scene` (the model's colours
// set to black so only the overlay or pattern lights).
std::map<NodeId, cv::Mat> RenderAll(const Site3& s, const RenderContent& content) {
  Scene black = s.scene;
  for (Material& m : black.materials) {
    m.base_color_factor = Eigen::Vector4d(0, 0, 0, 1);
    m.base_color_texture = -1;
  }
  std::map<NodeId, cv::Mat> frames;
  for (const sim::UnitSpec& unit : s.site.units) {
    const CameraModel& model = unit.projector.model;
    Expected<std::unique_ptr<GlContext>> context =
        CreateEglContext(cv::Size(model.width_px, model.height_px));
    EXPECT_TRUE(context.ok());
    if (!context.ok()) return {};
    Expected<std::unique_ptr<Renderer>> renderer = Renderer::Create(context->get(), black);
    EXPECT_TRUE(renderer.ok());
    Expected<ProjectorView> view =
        PrepareProjectorView(model, unit.projector.table_from_projector.Inverse(), black.Bounds());
    EXPECT_TRUE(view.ok());
    EXPECT_TRUE((*renderer)->SetView(*view).ok());
    EXPECT_TRUE((*renderer)->Render(content).ok());
    Expected<cv::Mat> frame = (*context)->ReadOutput();
    EXPECT_TRUE(frame.ok());
    frames[unit.id] = *frame;
  }
  return frames;
}

TEST(ShowThroughWorldTest, AStrokeAppearsOnEveryProjectorThatLightsItAndNoneOccluded) {
  Site3 s = MakeSite();
  ASSERT_TRUE(s.world);
  // A table point lit by some projectors and occluded for another by a building well in front.
  std::optional<Eigen::Vector3d> point;
  std::vector<NodeId> lit, occluded;
  for (double y = -0.5; y <= 0.5 && !point; y += 0.02) {
    for (double x = -0.5; x <= 0.5 && !point; x += 0.02) {
      Expected<sim::SurfaceTruth> truth = s.world->TruthAtTableXY(Eigen::Vector2d(x, y));
      if (!truth.ok() || std::abs(truth->point_in_table_m.z()) > 1e-6) continue;
      std::vector<NodeId> l, o;
      for (const sim::ProjectorTruth& p : truth->projectors) {
        if (p.sample.visible) {
          l.push_back(p.unit);
          continue;
        }
        if (!p.sample.projectable) continue;
        // Occluded (not just facing away or off the image): a surface between the point and the
        // projector, far enough in front.
        const Eigen::Vector3d centre =
            s.site.FindUnit(p.unit)->projector.table_from_projector.translation;
        const Eigen::Vector3d from = truth->point_in_table_m + Eigen::Vector3d(0, 0, 1e-4);
        const std::optional<RayHit> hit = s.world->caster().Intersect(from, centre - from);
        if (hit && hit->distance_m > kOccluderDistance_m &&
            hit->distance_m < (centre - from).norm()) {
          o.push_back(p.unit);
        }
      }
      if (!l.empty() && !o.empty()) {
        point = truth->point_in_table_m;
        lit = l;
        occluded = o;
      }
    }
  }
  ASSERT_TRUE(point.has_value()) << "no table point both lit and occluded on sandtable-3";
  RenderContent content;
  Polyline stroke;
  stroke.points_in_table_m = {*point - Eigen::Vector3d(0.015, 0, 0),
                              *point + Eigen::Vector3d(0.015, 0, 0)};
  stroke.width_m = 0.012;
  stroke.colour = Eigen::Vector3f(1, 1, 1);
  content.strokes = {stroke};
  content.overlay_version = 1;
  const std::map<NodeId, cv::Mat> frames = RenderAll(s, content);
  ASSERT_EQ(frames.size(), s.site.units.size());
  for (const auto& [id, frame] : frames) ASSERT_TRUE(s.world->SetProjectorFrame(id, frame).ok());
  // From above, 10 cm around the point, one projector lit at a time: the stroke's centre
  // against the mean of the view's border (black model, ambient light).
  const Eigen::AlignedBox2d area(point->head<2>() - Eigen::Vector2d(0.05, 0.05),
                                 point->head<2>() + Eigen::Vector2d(0.05, 0.05));
  const sim::View top = sim::View::OrthographicTop(area, 101, 101);
  for (const sim::UnitSpec& unit : s.site.units) {
    Expected<std::vector<float>> lum = s.world->RenderLuminanceLit(top, {unit.id});
    ASSERT_TRUE(lum.ok()) << lum.status().ToString();
    const double centre = (*lum)[50 * 101 + 50];
    double border = 0.0;
    for (int i = 0; i < 101; ++i) border += (*lum)[i] + (*lum)[100 * 101 + i];
    border /= 202.0;
    const bool is_lit = std::count(lit.begin(), lit.end(), unit.id) > 0;
    const bool is_occluded = std::count(occluded.begin(), occluded.end(), unit.id) > 0;
    std::cout << "unit " << unit.id
              << (is_lit        ? " lights"
                  : is_occluded ? " occluded"
                                : " neither")
              << ": stroke " << centre << " cd/m2, surroundings " << border << " cd/m2\n";
    if (is_lit) {
      EXPECT_GT(centre, kShownContrast * border) << "unit " << unit.id << " lights the point";
    }
    if (is_occluded) {
      EXPECT_LT(centre, kHiddenContrast * border) << "unit " << unit.id << " is occluded there";
    }
  }
}

}  // namespace
}  // namespace sandtable::node
