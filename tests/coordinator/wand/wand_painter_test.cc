// Wand painting end to end without sockets: a virtual-wand script drives WandService on a
// made-up clock (PollEvents); the painted events go through AnnotationStore::Commit (the
// persisted path the AnnotationService uses) and the resulting annotation state is checked:
// stroke points on the interpolated path with the spacing respected, the rim palette changes
// the colour of the next stroke, the spot eraser cuts a stroke, clear-all clears.
#include "coordinator/wand/wand_painter.h"

#include <gtest/gtest.h>

#include <iterator>
#include <memory>
#include <sstream>

#include "coordinator/annotations/annotation_store.h"
#include "coordinator/tracker/virtual_wand.h"
#include "coordinator/wand/wand_service.h"

namespace sandtable::coordinator {
namespace {

using cluster::Stroke;

constexpr int64_t kStart_ns = 7'000'000'000;
// Points are float on the wire: ~3e-8 m resolution at 0.3 m; the path itself is exact in double.
constexpr double kFloatPoint_m = 1e-7;
constexpr double kMinSpacing_m = 0.002;
constexpr double kEraserRadius_m = 0.02;

std::string At(double t_s, const Eigen::Vector3d& xy) {
  std::ostringstream out;
  out.precision(17);
  out << "at " << t_s << " " << xy.x() << " " << xy.y() << " 0.3 0 0 -1\n";
  return out.str();
}

class WandPainterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(":memory:");
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    store_ = std::move(*store);
  }
  // Polls the service at kStart_ns + t_s and commits what it painted.
  void Advance(WandService& service, double t_s) {
    service.PollEvents(kStart_ns + static_cast<int64_t>(t_s * 1e9));
    Expected<CommitReport> report = store_->Commit(&pending_);
    ASSERT_TRUE(report.ok()) << report.status().ToString();
    for (const Status& s : report->results) ASSERT_TRUE(s.ok()) << s.ToString();
    committed_ += pending_.size();
    pending_.clear();
  }
  std::unique_ptr<AnnotationStore> store_;
  std::vector<wire::AnnotationEvent> pending_;
  size_t committed_ = 0;
};

TEST_F(WandPainterTest, ScriptedWandDrawsPicksColourErasesAndClears) {
  const PaletteLayout palette;
  const Eigen::Vector3d blue = palette.SwatchCenter(2);
  const Eigen::Vector3d eraser = palette.SwatchCenter(5);
  const Eigen::Vector3d clear = palette.SwatchCenter(6);
  ASSERT_EQ(palette.swatches[2].color_rgb, Eigen::Vector3f(0.f, 0.f, 1.f));
  ASSERT_EQ(palette.swatches[5].tool, PaletteTool::kEraser);
  ASSERT_EQ(palette.swatches[6].tool, PaletteTool::kClear);
  const Eigen::Vector3d a(-0.2, 0.0, 0.0), b(-0.05, 0.0, 0.0);  // stroke 1: 1.5 mm per sample
  std::string script = "rate_hz 100\n";
  script += At(0.0, a) + At(1.0, b) + "down 0.0\nup 1.0\n";
  script += At(2.0, blue) + At(2.3, blue) + "down 2.1\nup 2.2\n";
  script += At(2.5, {0.1, 0.1, 0}) + At(3.0, {0.2, 0.1, 0}) + "down 2.6\nup 2.9\n";
  script += At(3.5, eraser) + At(3.8, eraser) + "down 3.6\nup 3.7\n";
  script += At(4.0, {-0.125, 0.05, 0}) + At(4.4, {-0.125, -0.05, 0}) + "down 4.05\nup 4.35\n";
  script += At(5.0, clear) + At(5.3, clear) + "down 5.1\nup 5.2\n";
  Expected<VirtualWandScript> parsed = ParseVirtualWandScript(script, "test");
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();

  WandService service(std::make_unique<VirtualWandSource>("test", *parsed), WandServiceOptions{});
  WandPainterOptions painter_options;
  painter_options.min_spacing_m = kMinSpacing_m;
  painter_options.eraser_radius_m = kEraserRadius_m;
  service.EnablePainting(
      painter_options, [this](wire::AnnotationEvent e) { pending_.push_back(std::move(e)); },
      [this] { return store_->last_sequence() + 1 + pending_.size(); });

  // Stroke 1 (red, the initial colour): samples 0..99 held, points every 2nd sample.
  Advance(service, 0.0);
  Advance(service, 1.95);
  ASSERT_EQ(store_->state().strokes().size(), 1u);
  const Stroke& first = store_->state().strokes().begin()->second;
  EXPECT_GE(first.id, kWandStrokeIdBit);
  EXPECT_TRUE(first.ended);
  EXPECT_EQ(first.color_rgb, Eigen::Vector3f(1.f, 0.f, 0.f));
  EXPECT_FLOAT_EQ(first.width_m, 0.005f);
  // Expected: the interpolated path at t_k = k / 100, greedily thinned to >= 2 mm.
  std::vector<Eigen::Vector3d> expected;
  for (int k = 0; k < 100; ++k) {
    const double s = (k / 100.0) / 1.0;
    const Eigen::Vector3d p = (1 - s) * a + s * b;
    if (expected.empty() || (p - expected.back()).norm() >= kMinSpacing_m) expected.push_back(p);
  }
  ASSERT_EQ(first.points_in_table_m.size(), expected.size());
  EXPECT_EQ(expected.size(), 50u);
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_LT((first.points_in_table_m[i].cast<double>() - expected[i]).norm(), kFloatPoint_m) << i;
    if (i > 0) {
      EXPECT_GE((first.points_in_table_m[i] - first.points_in_table_m[i - 1]).norm(),
                kMinSpacing_m - kFloatPoint_m);
    }
  }

  // Blue swatch pressed: no stroke there; the next stroke is blue.
  Advance(service, 3.4);
  ASSERT_EQ(store_->state().strokes().size(), 2u);
  const Stroke& second = std::next(store_->state().strokes().begin())->second;
  EXPECT_GT(second.id, first.id);
  EXPECT_EQ(second.color_rgb, Eigen::Vector3f(0.f, 0.f, 1.f));
  ASSERT_FALSE(second.points_in_table_m.empty());
  for (const Eigen::Vector3f& p : second.points_in_table_m) {
    EXPECT_NEAR(p.y(), 0.1, kFloatPoint_m);
    EXPECT_NEAR(p.z(), 0.0, kFloatPoint_m);
  }
  EXPECT_EQ(service.painter()->color_rgb(), Eigen::Vector3f(0.f, 0.f, 1.f));

  // Eraser swatch, then a drag across stroke 1 at x = -0.125: stroke 1 is cut in two.
  Advance(service, 4.9);
  EXPECT_EQ(service.painter()->tool(), PaletteTool::kEraser);
  EXPECT_EQ(store_->state().strokes().size(), 3u);
  for (const auto& [id, stroke] : store_->state().strokes()) {
    for (const Eigen::Vector3f& p : stroke.points_in_table_m) {
      EXPECT_GT((p.cast<double>() - Eigen::Vector3d(-0.125, 0, 0)).norm(), 0.015) << id;
    }
  }

  // Clear-all swatch.
  Advance(service, 10.0);
  EXPECT_TRUE(store_->state().strokes().empty());
  EXPECT_EQ(service.source().state(), TrackerState::kEnded);
  EXPECT_EQ(service.counters().annotation_events, committed_);
}

TEST(PaletteLayoutTest, SwatchesCoverTheRingSegmentInOrder) {
  const PaletteLayout palette;
  ASSERT_TRUE(palette.Check().ok());
  for (size_t i = 0; i < palette.swatches.size(); ++i) {
    ASSERT_EQ(palette.SwatchAt(palette.SwatchCenter(i)).value_or(99), i);
  }
  EXPECT_FALSE(palette.SwatchAt({0.0, 0.0, 0.0}).has_value());    // table centre
  EXPECT_FALSE(palette.SwatchAt({0.0, 0.95, 0.0}).has_value());   // far rim, outside the segment
  EXPECT_FALSE(palette.SwatchAt({0.0, -1.05, 0.0}).has_value());  // beyond the outer radius
  PaletteLayout wrapped;                                          // a segment across +-180 deg
  wrapped.start_angle_deg = 150.0;
  wrapped.end_angle_deg = 210.0;
  EXPECT_EQ(wrapped.SwatchAt({-0.95, -0.01, 0.0}).value_or(99), 3u);
  EXPECT_EQ(wrapped.SwatchAt({-0.95, 0.01, 0.0}).value_or(99), 3u);
  PaletteLayout bad;
  bad.outer_radius_m = 0.5;
  EXPECT_FALSE(bad.Check().ok());
}

}  // namespace
}  // namespace sandtable::coordinator
