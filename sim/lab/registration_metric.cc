#include "sim/lab/registration_metric.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <set>

#include "common/base/units.h"
#include "common/estimation/umeyama.h"

namespace sandtable::sim {

namespace {

// Uniform in [0, 1) from mt19937_64 with a fully specified mapping (53 bits), so a seed gives
// the same samples on every platform (std::uniform_real_distribution is not specified).
class Uniform01 {
 public:
  explicit Uniform01(uint64_t seed) : engine_(seed) {}
  double Next() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }

 private:
  std::mt19937_64 engine_;
};

Eigen::Vector3d Vertex(const Scene& scene, int triangle, int corner) {
  return scene.positions_in_table_m[scene.triangles[triangle][corner]].cast<double>();
}

struct Accumulator {
  std::vector<double> mm, px;
  void Add(const RegistrationSample& s) {
    mm.push_back(s.error_mm);
    px.push_back(s.error_px);
  }
};

struct ErrorsAccumulator {
  Accumulator all, table, buildings;
  int unmeasured = 0;
  void Add(const RegistrationSample& s) {
    all.Add(s);
    (s.surface == SurfaceClass::kTable ? table : buildings).Add(s);
  }
  RegistrationErrors Finish() const {
    RegistrationErrors out;
    out.all = ErrorStats::From(all.mm, all.px);
    out.table = ErrorStats::From(table.mm, table.px);
    out.buildings = ErrorStats::From(buildings.mm, buildings.px);
    out.unmeasured = unmeasured;
    return out;
  }
};

}  // namespace

double Quantile(std::vector<double> values, double q) {
  if (values.empty()) return 0.0;
  const size_t rank = static_cast<size_t>(std::ceil(q * static_cast<double>(values.size())));
  const size_t index = std::clamp<size_t>(rank, 1, values.size()) - 1;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(index),
                   values.end());
  return values[index];
}

Status RegistrationMetricOptions::Check() const {
  if (num_samples < 1) return InvalidArgumentError("registration metric: num_samples must be >= 1");
  if (!(max_incidence_deg > 0 && max_incidence_deg <= 90)) {
    return InvalidArgumentError("registration metric: max_incidence_deg must be in (0, 90]");
  }
  if (!(table_height_tolerance_m >= 0) || !std::isfinite(table_height_tolerance_m)) {
    return InvalidArgumentError("registration metric: table_height_tolerance_m must be >= 0");
  }
  if (!(table_normal_min_z > 0 && table_normal_min_z <= 1)) {
    return InvalidArgumentError("registration metric: table_normal_min_z must be in (0, 1]");
  }
  if (!true_table_from_model.AllFinite()) {
    return InvalidArgumentError("registration metric: true_table_from_model is not finite");
  }
  return OkStatus();
}

ErrorStats ErrorStats::From(const std::vector<double>& errors_mm,
                            const std::vector<double>& errors_px) {
  ErrorStats s;
  s.count = static_cast<int>(errors_mm.size());
  if (s.count == 0) return s;
  double sum = 0, sum_sq = 0, sum_sq_px = 0;
  for (double e : errors_mm) {
    sum += e;
    sum_sq += e * e;
    s.max_mm = std::max(s.max_mm, e);
  }
  for (double e : errors_px) {
    sum_sq_px += e * e;
    s.max_px = std::max(s.max_px, e);
  }
  s.mean_mm = sum / s.count;
  s.rms_mm = std::sqrt(sum_sq / s.count);
  s.rms_px = std::sqrt(sum_sq_px / static_cast<double>(errors_px.size()));
  s.p99_mm = Quantile(errors_mm, 0.99);
  s.p99_px = Quantile(errors_px, 0.99);
  return s;
}

SurfaceClass ClassifyTriangle(const Scene& scene, int triangle,
                              const RegistrationMetricOptions& options) {
  for (int corner = 0; corner < 3; ++corner) {
    if (std::abs(Vertex(scene, triangle, corner).z()) > options.table_height_tolerance_m) {
      return SurfaceClass::kBuilding;
    }
  }
  return scene.FaceNormal(triangle).z() > options.table_normal_min_z ? SurfaceClass::kTable
                                                                     : SurfaceClass::kBuilding;
}

std::optional<RegistrationSample> RegistrationErrorAt(const ProjectorSpec& truth,
                                                      const EstimatedRegistration& estimate,
                                                      const Rigid3d& true_table_from_model,
                                                      const Eigen::Vector3d& point_in_table_m,
                                                      const Eigen::Vector3d& plane_normal) {
  RegistrationSample s;
  s.unit_id = estimate.unit_id;
  s.point_in_table_m = point_in_table_m;
  const Eigen::Vector3d point_in_model_m = true_table_from_model.Inverse() * point_in_table_m;
  // u_hat: projector_from_model_est = projector_from_table_est * table_from_model_est.
  const Rigid3d projector_from_model_est =
      estimate.table_from_projector.Inverse() * estimate.table_from_model;
  const std::optional<Eigen::Vector2d> estimated =
      estimate.projector.Project(projector_from_model_est * point_in_model_m);
  const Rigid3d projector_from_table_true = truth.table_from_projector.Inverse();
  const std::optional<Eigen::Vector2d> true_pixel =
      truth.model.Project(projector_from_table_true * point_in_table_m);
  if (!estimated || !true_pixel) return std::nullopt;
  s.estimated_pixel_px = *estimated;
  s.true_pixel_px = *true_pixel;
  // The true ray through u_hat, intersected with the plane n . (x - X) = 0:
  //   x = c + s d,  s = n . (X - c) / (n . d).
  const Expected<Eigen::Vector3d> ray_in_projector = truth.model.Unproject(*estimated);
  if (!ray_in_projector.ok()) return std::nullopt;
  const Eigen::Vector3d centre = truth.table_from_projector.translation;
  const Eigen::Vector3d direction = (truth.table_from_projector.rotation * *ray_in_projector);
  const double denominator = plane_normal.dot(direction);
  // Below 1e-12 the ray runs within 1e-12 rad of the plane: no meaningful intersection.
  constexpr double kMinCosine = 1e-12;
  if (std::abs(denominator) < kMinCosine * direction.norm()) return std::nullopt;
  const double along = plane_normal.dot(point_in_table_m - centre) / denominator;
  if (!(along > 0) || !std::isfinite(along)) return std::nullopt;
  s.hit_in_table_m = centre + along * direction;
  s.error_mm = (s.hit_in_table_m - point_in_table_m).norm() * 1e3;
  s.error_px = (s.estimated_pixel_px - s.true_pixel_px).norm();
  return s;
}

Expected<RegistrationReport> MeasureRegistration(
    const World& world, const std::vector<EstimatedRegistration>& estimates,
    const RegistrationMetricOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  const Site& site = world.site();
  const Scene& scene = world.scene();
  std::vector<const UnitSpec*> units;  // per estimate
  std::set<NodeId> seen;
  for (const EstimatedRegistration& e : estimates) {
    const UnitSpec* unit = site.FindUnit(e.unit_id);
    if (!unit) {
      return InvalidArgumentError("registration metric: calibration of unit " +
                                  std::to_string(e.unit_id) + " but the site '" + site.name +
                                  "' has no such unit");
    }
    if (!seen.insert(e.unit_id).second) {
      return InvalidArgumentError("registration metric: two calibrations of unit " +
                                  std::to_string(e.unit_id));
    }
    if (Status valid = e.projector.Check(); !valid.ok()) {
      return valid.WithContext("registration metric: unit " + std::to_string(e.unit_id) +
                               ": projector: ");
    }
    units.push_back(unit);
  }
  // Area-weighted sampling: cumulative triangle areas, then uniform barycentrics
  // (sqrt trick: p = (1 - sqrt r1) a + sqrt r1 (1 - r2) b + sqrt r1 r2 c is uniform on abc).
  std::vector<double> cumulative_area;
  cumulative_area.reserve(scene.triangles.size());
  double total_area = 0.0;
  for (int t = 0; t < scene.NumTriangles(); ++t) {
    const Eigen::Vector3d a = Vertex(scene, t, 0), b = Vertex(scene, t, 1), c = Vertex(scene, t, 2);
    total_area += 0.5 * (b - a).cross(c - a).norm();
    cumulative_area.push_back(total_area);
  }
  if (!(total_area > 0)) {
    return InvalidArgumentError("registration metric: the scene has no triangle of positive area");
  }
  const double min_cos_incidence = std::cos(DegToRad(options.max_incidence_deg));
  Uniform01 rng(options.seed);
  RegistrationReport report;
  report.num_candidates = options.num_samples;
  ErrorsAccumulator site_errors;
  std::map<NodeId, ErrorsAccumulator> unit_errors;
  for (const EstimatedRegistration& e : estimates) unit_errors[e.unit_id];
  for (int i = 0; i < options.num_samples; ++i) {
    const double pick = rng.Next() * total_area;
    const int t = static_cast<int>(
        std::min<ptrdiff_t>(std::upper_bound(cumulative_area.begin(), cumulative_area.end(), pick) -
                                cumulative_area.begin(),
                            scene.NumTriangles() - 1));
    const double r1 = std::sqrt(rng.Next()), r2 = rng.Next();
    const Eigen::Vector3d point = (1 - r1) * Vertex(scene, t, 0) +
                                  r1 * (1 - r2) * Vertex(scene, t, 1) +
                                  r1 * r2 * Vertex(scene, t, 2);
    const Eigen::Vector3d normal = scene.FaceNormal(t);
    if (normal.squaredNorm() == 0.0) continue;  // degenerate triangle (zero area: never picked)
    const SurfaceClass surface = ClassifyTriangle(scene, t, options);
    bool lit = false;
    for (size_t k = 0; k < estimates.size(); ++k) {
      const ProjectorSpec& truth = units[k]->projector;
      Expected<ProjectorTruth> light = world.ProjectorTruthAtPoint(units[k]->id, point);
      if (!light.ok() || !light->sample.visible) continue;
      const Eigen::Vector3d to_projector = truth.table_from_projector.translation - point;
      const double cos_incidence = std::abs(normal.dot(to_projector)) / to_projector.norm();
      if (cos_incidence <= min_cos_incidence) continue;
      lit = true;
      std::optional<RegistrationSample> sample =
          RegistrationErrorAt(truth, estimates[k], options.true_table_from_model, point, normal);
      if (!sample) {
        ++site_errors.unmeasured;
        ++unit_errors[estimates[k].unit_id].unmeasured;
        continue;
      }
      sample->triangle = t;
      sample->surface = surface;
      site_errors.Add(*sample);
      unit_errors[estimates[k].unit_id].Add(*sample);
      if (options.keep_samples) report.samples.push_back(*sample);
    }
    if (lit) {
      ++report.num_lit_points;
      ++(surface == SurfaceClass::kTable ? report.num_table_points : report.num_building_points);
    }
  }
  report.site = site_errors.Finish();
  for (const auto& [id, errors] : unit_errors) report.per_unit[id] = errors.Finish();
  return report;
}

}  // namespace sandtable::sim

namespace sandtable::sim {

Expected<ModelPlacementError> MeasureModelPlacement(
    const World& world, const std::vector<EstimatedRegistration>& estimates,
    const Rigid3d& true_table_from_model, const Eigen::Vector3d& model_centre_in_model_m,
    int grid_step_px) {
  std::vector<Eigen::Vector3d> estimated, truth;
  for (const EstimatedRegistration& e : estimates) {
    const UnitSpec* unit = world.site().FindUnit(e.unit_id);
    if (!unit) continue;
    const ProjectorSpec& spec = unit->projector;
    for (int v = grid_step_px / 2; v < e.projector.height_px; v += grid_step_px) {
      for (int u = grid_step_px / 2; u < e.projector.width_px; u += grid_step_px) {
        const Eigen::Vector2d pixel(u, v);
        Expected<Eigen::Vector3d> est_ray = e.projector.Unproject(pixel);
        Expected<Eigen::Vector3d> true_ray = spec.model.Unproject(pixel);
        if (!est_ray.ok() || !true_ray.ok()) continue;
        const Eigen::Vector3d o = e.table_from_projector.translation;
        const Eigen::Vector3d d = e.table_from_projector.rotation * *est_ray;
        if (std::abs(d.z()) < 1e-9) continue;
        const double s = -o.z() / d.z();
        if (!(s > 0)) continue;
        Expected<SurfaceTruth> hit = world.TruthAlongRay(
            spec.table_from_projector.translation, spec.table_from_projector.rotation * *true_ray);
        if (!hit.ok() || std::abs(hit->point_in_table_m.z()) > 1e-4 ||
            hit->normal_in_table.z() < 0.999) {
          continue;
        }
        estimated.push_back(o + s * d);
        truth.push_back(hit->point_in_table_m);
      }
    }
  }
  if (estimated.size() < 10) {
    return DegenerateError("model placement: " + std::to_string(estimated.size()) +
                           " projector pixels land on the table (10 needed)");
  }
  Expected<RigidFitReport> fit = FitRigidUmeyama(estimated, truth);
  if (!fit.ok()) return fit.status();
  ModelPlacementError out;
  out.true_table_from_estimated_table = fit->target_from_source;
  out.pairs = static_cast<int>(estimated.size());
  out.frame_fit_rms_mm = fit->rms_m * 1e3;
  if (estimates.empty()) return out;
  const Rigid3d placed = out.true_table_from_estimated_table * estimates.front().table_from_model;
  out.offset_mm =
      (placed * model_centre_in_model_m - true_table_from_model * model_centre_in_model_m).norm() *
      1e3;
  out.offset_deg = Eigen::AngleAxisd((true_table_from_model.Inverse() * placed).rotation).angle() *
                   180.0 / 3.14159265358979323846;
  return out;
}

}  // namespace sandtable::sim
