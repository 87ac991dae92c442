// The predicted error of the cluster bundle (node/calibration/cluster_uncertainty.h) against
// the spread it predicts: a synthetic three-unit site whose observations carry Gaussian noise
// of a known sigma and whose factory values (the priors' means) are drawn about the truth with
// the priors' own sigmas, solved again and again. The rms of the solved projectors' pixel errors
// over the draws must match the rms the solves predicted; a flat site held only to a plane
// must name what it does not determine.
#include <cmath>
#include <map>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "node/calibration/cluster_bundle.h"
#include "node/calibration/cluster_uncertainty.h"

namespace sandtable {
namespace {

constexpr int kDraws = 30;
constexpr double kNoise_px = 0.1;
// Predicted and observed rms agree within this factor either way (30 draws of a handful of
// dominant directions: the observed rms itself scatters by ~15 %).
constexpr double kAgreementFactor = 1.5;
constexpr double kTablePredictionFactor = 3.0;  // mm vs px x footprint scale, see below

struct TrueUnit {
  NodeId id;
  node::UnitModel model;
  Rigid3d table_from_projector;
};

// Three projectors 1.4 m over the table, 0.55 m apart, looking down with small tilts; each
// camera 0.12 m beside its projector, yawed towards it.
std::vector<TrueUnit> MakeSite() {
  std::vector<TrueUnit> units;
  for (int i = 0; i < 3; ++i) {
    TrueUnit u;
    u.id = static_cast<NodeId>(i + 1);
    u.model.unit = u.id;
    u.model.projector = CameraModel(1280, 800, 1500, 1500, 640, 560, {0.02, 0.0, 0.0, 0.0, 0.0});
    u.model.camera =
        CameraModel(1280, 1024, 1000, 1000, 640, 512, {-0.12, 0.05, 0.0005, -0.0003, 0.0});
    const Eigen::Matrix3d down = Eigen::Vector3d(1, -1, -1).asDiagonal();
    const Eigen::Matrix3d tilt =
        Eigen::AngleAxisd((i - 1) * 6.0 * M_PI / 180.0, Eigen::Vector3d::UnitY())
            .toRotationMatrix();
    u.table_from_projector = Rigid3d(tilt * down, Eigen::Vector3d(0.55 * (i - 1), 0.05, 1.4));
    u.model.projector_from_camera =
        Rigid3d(Eigen::AngleAxisd(-5.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix(),
                Eigen::Vector3d(0.12, 0.0, 0.0));
    units.push_back(u);
  }
  return units;
}

// Table points on a jittered grid, plus a block 0.12 m high (relief, so the scale and the
// focal lengths are told apart by more than the mounts).
std::vector<Eigen::Vector3d> MakePoints(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> jitter(-0.01, 0.01);
  std::vector<Eigen::Vector3d> points;
  for (double x = -1.0; x <= 1.0; x += 0.04) {
    for (double y = -0.45; y <= 0.55; y += 0.04) {
      const bool block = std::abs(x - 0.1) < 0.15 && std::abs(y - 0.1) < 0.12;
      points.emplace_back(x + jitter(rng), y + jitter(rng), block ? 0.12 : 0.0);
    }
  }
  return points;
}

struct Draw {
  node::ClusterObservations observations;
  std::map<NodeId, Rigid3d> projector_from_world;  // truth, world = the root projector's frame
};

// Factory values about the truth with the bundle's prior sigmas; observations with noise.
Draw MakeDraw(const std::vector<TrueUnit>& units, const std::vector<Eigen::Vector3d>& points,
              const node::BundleOptions& options, std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Draw d;
  const Rigid3d root_from_table = units[0].table_from_projector.Inverse();
  for (const TrueUnit& u : units) {
    d.projector_from_world[u.id] = u.table_from_projector.Inverse() * root_from_table.Inverse();
    node::UnitModel factory = u.model;
    for (CameraModel* m : {&factory.projector, &factory.camera}) {
      m->fx_px *= 1.0 + options.prior_focal_relative * g(rng);
      m->fy_px *= 1.0 + options.prior_focal_relative * g(rng);
      m->cx_px += options.prior_principal_point_px * g(rng);
      m->cy_px += options.prior_principal_point_px * g(rng);
      m->distortion.k1 += options.prior_k1 * g(rng);
      m->distortion.k2 += options.prior_k2 * g(rng);
      m->distortion.p1 += options.prior_p * g(rng);
      m->distortion.p2 += options.prior_p * g(rng);
    }
    const double r = options.prior_mount_rotation_deg * M_PI / 180.0;
    const Eigen::Vector3d axis(r * g(rng), r * g(rng), r * g(rng));
    const Rigid3d mount_error(
        Eigen::AngleAxisd(axis.norm(), axis.normalized()).toRotationMatrix(),
        Eigen::Vector3d(g(rng), g(rng), g(rng)) * options.prior_mount_translation_m);
    // The prior is on camera_from_projector; its error composes on that side.
    factory.projector_from_camera =
        (mount_error * u.model.projector_from_camera.Inverse()).Inverse();
    d.observations.units[u.id] = factory;
  }
  for (const Eigen::Vector3d& x_in_table : points) {
    const Eigen::Vector3d x = root_from_table * x_in_table;
    for (const TrueUnit& p : units) {
      const std::optional<Eigen::Vector2d> up =
          p.model.projector.Project(d.projector_from_world.at(p.id) * x);
      if (!up || !p.model.projector.InImage(*up)) continue;
      node::Track t;
      t.projector_unit = p.id;
      t.projector_px = *up + kNoise_px * Eigen::Vector2d(g(rng), g(rng));
      for (const TrueUnit& c : units) {
        const Rigid3d camera_from_world =
            c.model.projector_from_camera.Inverse() * d.projector_from_world.at(c.id);
        const std::optional<Eigen::Vector2d> uc = c.model.camera.Project(camera_from_world * x);
        if (!uc || !c.model.camera.InImage(*uc)) continue;
        t.cameras.push_back({c.id, *uc + kNoise_px * Eigen::Vector2d(g(rng), g(rng))});
      }
      if (!t.cameras.empty()) d.observations.tracks.push_back(t);
    }
  }
  return d;
}

TEST(ClusterUncertainty, PredictsTheSpreadOfTheSolvedProjectors) {
  std::mt19937_64 rng(17);
  const std::vector<TrueUnit> units = MakeSite();
  const std::vector<Eigen::Vector3d> points = MakePoints(rng);
  node::BundleOptions options;
  options.observation_sigma_px = kNoise_px;
  std::map<NodeId, double> observed_sq, predicted_sq;
  std::map<NodeId, int> observed_n;
  for (int draw = 0; draw < kDraws; ++draw) {
    const Draw d = MakeDraw(units, points, options, rng);
    Expected<node::BundleResult> solved =
        node::AdjustCluster(d.observations, d.projector_from_world, 1, options);
    ASSERT_TRUE(solved.ok()) << solved.status().message();
    ASSERT_TRUE(solved->report.uncertainty_note.empty()) << solved->report.uncertainty_note;
    EXPECT_NEAR(solved->report.sigma_px, kNoise_px, 0.2 * kNoise_px);
    EXPECT_TRUE(solved->report.undetermined.empty()) << solved->report.undetermined;
    const Rigid3d root_from_table = units[0].table_from_projector.Inverse();
    for (const TrueUnit& u : units) {
      const node::UnitBundleReport& r = solved->report.units.at(u.id);
      ASSERT_GT(r.predicted_rms_px, 0.0) << "unit " << u.id;
      EXPECT_FALSE(r.weak_direction.empty());
      predicted_sq[u.id] += r.predicted_rms_px * r.predicted_rms_px;
      // The solved projector against the true one, at the table points it lights.
      const CameraModel& estimated = solved->units.at(u.id).projector;
      const Rigid3d& estimated_pose = solved->projector_from_world.at(u.id);
      for (const Eigen::Vector3d& x_in_table : points) {
        const Eigen::Vector3d x = root_from_table * x_in_table;
        const auto truth = u.model.projector.Project(d.projector_from_world.at(u.id) * x);
        const auto est = estimated.Project(estimated_pose * x);
        if (!truth || !est || !u.model.projector.InImage(*truth)) continue;
        observed_sq[u.id] += (*est - *truth).squaredNorm();
        ++observed_n[u.id];
      }
    }
  }
  for (const TrueUnit& u : units) {
    const double predicted = std::sqrt(predicted_sq[u.id] / kDraws);
    const double observed = std::sqrt(observed_sq[u.id] / observed_n[u.id]);
    std::cout << "unit " << u.id << ": predicted " << predicted << " px, observed " << observed
              << " px over " << kDraws << " draws\n";
    EXPECT_LT(observed, kAgreementFactor * predicted) << "unit " << u.id;
    EXPECT_GT(observed, predicted / kAgreementFactor) << "unit " << u.id;
  }
}

TEST(ClusterUncertainty, CarriesThePredictionToTheTable) {
  std::mt19937_64 rng(5);
  const std::vector<TrueUnit> units = MakeSite();
  const std::vector<Eigen::Vector3d> points = MakePoints(rng);
  node::BundleOptions options;
  options.observation_sigma_px = kNoise_px;
  const Draw d = MakeDraw(units, points, options, rng);
  Expected<node::BundleResult> solved =
      node::AdjustCluster(d.observations, d.projector_from_world, 1, options);
  ASSERT_TRUE(solved.ok()) << solved.status().message();
  // The solution's points in the true table frame, and each unit's solved pose there.
  const Rigid3d table_from_world = units[0].table_from_projector;
  std::vector<Eigen::Vector3d> in_table;
  for (const Eigen::Vector3d& p : solved->points_in_world) in_table.push_back(table_from_world * p);
  std::map<NodeId, UnitCalibration> calibrations;
  for (const TrueUnit& u : units) {
    UnitCalibration c;
    c.projector = solved->units.at(u.id).projector;
    c.table_from_projector = table_from_world * solved->projector_from_world.at(u.id).Inverse();
    calibrations[u.id] = c;
  }
  node::PredictOnTable(solved->report, solved->predicted, in_table, &calibrations);
  for (const TrueUnit& u : units) {
    ASSERT_TRUE(calibrations[u.id].predicted_error) << "unit " << u.id;
    const PredictedErrorRecord& p = *calibrations[u.id].predicted_error;
    ASSERT_GE(p.rms_mm, 0.0) << "unit " << u.id << ": " << p.samples << " samples";
    // A pixel of this projector covers 1.4 m / 1500 px ~ 0.93 mm of the table (more where it
    // looks obliquely): the mm figure is the px figure times about that.
    const double footprint_mm_per_px = 1.4e3 / 1500.0;
    EXPECT_GT(p.rms_mm, p.rms_px * footprint_mm_per_px / kTablePredictionFactor);
    EXPECT_LT(p.rms_mm, p.rms_px * footprint_mm_per_px * kTablePredictionFactor);
    EXPECT_EQ(p.sigma_px, solved->report.sigma_px);
  }
}

TEST(ClusterUncertainty, ASiteHeldOnlyToAPlaneNamesWhatItDoesNotFix) {
  std::mt19937_64 rng(9);
  const std::vector<TrueUnit> units = MakeSite();
  const std::vector<Eigen::Vector3d> points = MakePoints(rng);
  node::BundleOptions options;
  options.observation_sigma_px = kNoise_px;
  const Draw d = MakeDraw(units, points, options, rng);
  // A warm start that ties every point to the table plane and holds no pose (the planar
  // path's refinement): sliding or turning the whole site on the plane changes nothing.
  Expected<node::BundleResult> first =
      node::AdjustCluster(d.observations, d.projector_from_world, 1, options);
  ASSERT_TRUE(first.ok());
  const Rigid3d table_from_world = units[0].table_from_projector;
  node::BundleResult previous = *first;
  for (auto& [id, pose] : previous.projector_from_world) pose = pose * table_from_world.Inverse();
  for (Eigen::Vector3d& p : previous.points_in_world) p = table_from_world * p;
  node::BundleWarmStart warm;
  warm.previous = &previous;
  for (size_t i = 0; i < previous.points_in_world.size(); ++i) {
    if (std::abs(previous.points_in_world[i].z()) < 0.01) {
      warm.surface.push_back(
          {static_cast<int>(i), Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()});
    }
  }
  Expected<node::BundleResult> planar =
      node::AdjustCluster(d.observations, previous.projector_from_world, 1, options, &warm);
  ASSERT_TRUE(planar.ok()) << planar.status().message();
  // x, y and the turn about z at least (scale is held by the mounts' priors).
  EXPECT_NE(planar->report.undetermined.find("direction(s) the data do not fix"), std::string::npos)
      << planar->report.undetermined;
  EXPECT_NE(planar->report.undetermined.find("pose"), std::string::npos);
  for (const TrueUnit& u : units) EXPECT_GT(planar->report.units.at(u.id).predicted_rms_px, 0.0);
}

}  // namespace
}  // namespace sandtable
