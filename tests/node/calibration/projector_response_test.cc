// A projector's response (gamma, black level) fitted from captures of its own camera, through the
// simulated world's photometry (projector power law and black level, ambient light, camera noise
// and 8-bit quantisation): the fit finds the world's values for gammas and black levels unlike the
// preset's, with another projector's steady light in the camera, and refuses bad captures.
#include "node/calibration/projector_response.h"

#include <cmath>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "node/calibration/structured_light_plan.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"

namespace sandtable::node {
namespace {

// Named tolerances. The gamma comes from three grey levels averaged over ~10^5 camera pixels;
// the black level (0.2-1 % of peak) is a fraction of one 8-bit code per pixel, averaged.
constexpr double kGammaTolerance = 0.03;
constexpr double kBlackLevelTolerance = 5e-4;  // fraction of peak
constexpr int kLitThreshold = 20;
// Uniform captures rounded to whole codes: the darkest grey (about 10 codes over black) is off
// by up to half a code, 5 % of its ratio.
constexpr double kQuantisedGammaTolerance = 0.1;

struct Captured {
  cv::Mat black, white, muted;
  std::vector<std::pair<int, cv::Mat>> greys;
};

// Unit `id` shows black, white, the greys and is muted; `other` (if any) shows white throughout.
Expected<Captured> CaptureResponse(sim::World& world, NodeId id, NodeId other,
                                   const std::vector<int>& levels) {
  for (const sim::UnitSpec& u : world.site().units) {
    ST_RETURN_IF_ERROR(world.SetProjectorUniform(u.id, u.id == other ? 255 : 0));
  }
  const int bits = world.site().FindUnit(id)->camera->bit_depth;
  uint64_t seed = 11;
  auto capture = [&]() -> Expected<cv::Mat> {
    Expected<cv::Mat> image = world.Capture(id, sim::CaptureNoise{.enabled = true, .seed = seed++});
    if (!image.ok()) return image.status();
    return To8Bit(*image, bits).clone();
  };
  Captured c;
  Expected<cv::Mat> image = capture();
  if (!image.ok()) return image.status();
  c.black = *image;
  ST_RETURN_IF_ERROR(world.SetProjectorUniform(id, 255));
  if (!(image = capture()).ok()) return image.status();
  c.white = *image;
  for (int level : levels) {
    ST_RETURN_IF_ERROR(world.SetProjectorUniform(id, level));
    if (!(image = capture()).ok()) return image.status();
    c.greys.emplace_back(level, *image);
  }
  ST_RETURN_IF_ERROR(world.SetProjectorOn(id, false));
  if (!(image = capture()).ok()) return image.status();
  c.muted = *image;
  ST_RETURN_IF_ERROR(world.SetProjectorOn(id, true));
  return c;
}

// Uniform 8-bit captures of a projector with this response (black 10, white 210 codes).
Captured Uniform(double gamma, const std::vector<int>& levels) {
  Captured c;
  c.black = cv::Mat(40, 40, CV_8UC1, cv::Scalar(10));
  c.white = cv::Mat(40, 40, CV_8UC1, cv::Scalar(210));
  for (int level : levels) {
    const double value = 10.0 + 200.0 * std::pow(level / 255.0, gamma);
    c.greys.emplace_back(level, cv::Mat(40, 40, CV_8UC1, cv::Scalar(std::round(value))));
  }
  return c;
}

TEST(ProjectorResponse, AGammaNoProjectorHasIsRefusedNamingIt) {
  const Captured plausible = Uniform(2.2, {64, 128, 192});
  Expected<ProjectorResponse> ok =
      FitProjectorResponse(plausible.black, plausible.white, cv::Mat(), plausible.greys, cv::Mat());
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_NEAR(ok->gamma, 2.2, kQuantisedGammaTolerance);
  const Captured flat = Uniform(0.64, {64, 128, 192});  // a camera applying its own gamma
  Expected<ProjectorResponse> refused =
      FitProjectorResponse(flat.black, flat.white, cv::Mat(), flat.greys, cv::Mat());
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kOutOfRange);
  EXPECT_NE(refused.status().message().find("gamma 0.6"), std::string::npos)
      << refused.status().message();
}

class ProjectorResponseTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Expected<ProceduralScene> scene = MakeProceduralScene({});
    ASSERT_TRUE(scene.ok());
    scene_ = scene->scene;
  }
  Scene scene_;
};

TEST_F(ProjectorResponseTest, FindsTheWorldsGammaAndBlackLevel) {
  struct Case {
    double gamma, black_level;
  };
  for (const Case& truth : {Case{2.2, 0.002}, Case{1.8, 0.01}, Case{2.6, 0.004}}) {
    SCOPED_TRACE("gamma " + std::to_string(truth.gamma) + ", black " +
                 std::to_string(truth.black_level));
    Expected<sim::Site> site = sim::MakeSitePreset("sandtable-3");
    ASSERT_TRUE(site.ok());
    site->units[0].projector.gamma = truth.gamma;
    site->units[0].projector.black_level = truth.black_level;
    Expected<std::unique_ptr<sim::World>> world = sim::World::Create(*site, scene_);
    ASSERT_TRUE(world.ok()) << world.status().ToString();
    // Unit 1's white lights part of what unit 0's camera sees: steady light that cancels.
    Expected<Captured> c =
        CaptureResponse(**world, site->units[0].id, site->units[1].id, {64, 128, 192});
    ASSERT_TRUE(c.ok()) << c.status().ToString();
    const cv::Mat lit = LitMask(c->white, c->black, kLitThreshold);
    Expected<ProjectorResponse> r =
        FitProjectorResponse(c->black, c->white, c->muted, c->greys, lit);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_NEAR(r->gamma, truth.gamma, kGammaTolerance);
    EXPECT_NEAR(r->black_level, truth.black_level, kBlackLevelTolerance);
    EXPECT_GT(r->pixels, 10000);
    EXPECT_LT(r->fit_rms, 0.01);
    // Without the muted capture there is no black level, and the gamma is the same.
    Expected<ProjectorResponse> no_black =
        FitProjectorResponse(c->black, c->white, cv::Mat(), c->greys, lit);
    ASSERT_TRUE(no_black.ok());
    EXPECT_LT(no_black->black_level, 0.0);
    EXPECT_DOUBLE_EQ(no_black->gamma, r->gamma);
  }
}

TEST_F(ProjectorResponseTest, RefusesCapturesThatDoNotFit) {
  const cv::Mat black(400, 640, CV_8UC1, cv::Scalar(10)), white(400, 640, CV_8UC1, cv::Scalar(200));
  const cv::Mat grey(400, 640, CV_8UC1, cv::Scalar(50));
  // Sizes, types, levels.
  EXPECT_EQ(FitProjectorResponse(black, white(cv::Rect(0, 0, 320, 200)).clone(), cv::Mat(),
                                 {{128, grey}}, cv::Mat())
                .status()
                .code(),
            StatusCode::kInvalidArgument);
  cv::Mat wide;
  grey.convertTo(wide, CV_16U);
  EXPECT_EQ(FitProjectorResponse(black, white, cv::Mat(), {{128, wide}}, cv::Mat()).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(FitProjectorResponse(black, white, cv::Mat(), {{0, grey}}, cv::Mat()).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(FitProjectorResponse(black, white, cv::Mat(), {}, cv::Mat()).status().code(),
            StatusCode::kInvalidArgument);
  // A projector that does not respond (grey as bright as black), one the camera does not see
  // (nothing lit) and one that saturates everywhere.
  EXPECT_EQ(
      FitProjectorResponse(black, white, cv::Mat(), {{128, black}}, cv::Mat()).status().code(),
      StatusCode::kDegenerate);
  EXPECT_EQ(FitProjectorResponse(black, white, cv::Mat(), {{128, grey}},
                                 cv::Mat::zeros(400, 640, CV_8UC1))
                .status()
                .code(),
            StatusCode::kDegenerate);
  const cv::Mat saturated(400, 640, CV_8UC1, cv::Scalar(255));
  EXPECT_EQ(
      FitProjectorResponse(black, saturated, cv::Mat(), {{128, grey}}, cv::Mat()).status().code(),
      StatusCode::kDegenerate);
  // A uniform 40 / 190 above black at level 128 is gamma log(50/190) / log(128/255).
  Expected<ProjectorResponse> r =
      FitProjectorResponse(black, white, cv::Mat(), {{128, grey}}, cv::Mat());
  ASSERT_TRUE(r.ok());
  EXPECT_NEAR(r->gamma, std::log(40.0 / 190.0) / std::log(128.0 / 255.0), 1e-12);
}

}  // namespace
}  // namespace sandtable::node
