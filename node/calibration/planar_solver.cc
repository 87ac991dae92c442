#include "node/calibration/planar_solver.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <set>

#include <Eigen/Dense>

#include "common/base/thread_cpu_time.h"
#include "common/estimation/resection.h"
#include "common/estimation/table_frame.h"
#include "common/estimation/triangulation.h"
#include "node/calibration/cluster_uncertainty.h"

namespace sandtable::node {
namespace {

// A camera's 2D frame on its plane: origin below the camera, x along the camera's x axis
// projected on the plane, y = normal x x (normal towards the camera: right-handed, z up).
struct PlaneFrame {
  PlanarityProbe probe;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 3, 2> axes = Eigen::Matrix<double, 3, 2>::Zero();
};

PlaneFrame MakePlaneFrame(const PlanarityProbe& probe) {
  PlaneFrame f;
  f.probe = probe;
  const Eigen::Vector3d n = probe.plane_in_camera.normal;
  f.origin = probe.plane_in_camera.Project(Eigen::Vector3d::Zero());
  Eigen::Vector3d x = Eigen::Vector3d::UnitX() - n.x() * n;
  if (x.norm() < 1e-3) x = Eigen::Vector3d::UnitY() - n.y() * n;
  x.normalize();
  f.axes.col(0) = x;
  f.axes.col(1) = n.cross(x);
  return f;
}

// Where a camera pixel's ray meets the camera's plane, in its 2D frame.
std::optional<Eigen::Vector2d> OnPlane(const CameraModel& camera, const PlaneFrame& frame,
                                       const Eigen::Vector2d& pixel) {
  Expected<Eigen::Vector3d> ray = camera.Unproject(pixel);
  if (!ray.ok()) return std::nullopt;
  const Plane& plane = frame.probe.plane_in_camera;
  const double along = plane.normal.dot(*ray);
  if (std::abs(along) < 1e-9) return std::nullopt;
  const double t = -plane.offset_m / along;
  if (!(t > 0.0) || !std::isfinite(t)) return std::nullopt;
  return Eigen::Vector2d(frame.axes.transpose() * (t * *ray - frame.origin));
}

// S(x) = [a -b; b a] x + t, as M(x) q with q = (a, b, tx, ty).
Eigen::Matrix<double, 2, 4> SimilarityRows(const Eigen::Vector2d& x) {
  Eigen::Matrix<double, 2, 4> m;
  m << x.x(), -x.y(), 1.0, 0.0, x.y(), x.x(), 0.0, 1.0;
  return m;
}

std::vector<ProjectorGridPoint> OwnCells(NodeId unit, const std::vector<Track>& tracks) {
  std::vector<ProjectorGridPoint> cells;
  for (const Track& t : tracks) {
    if (t.projector_unit != unit) continue;
    for (const CameraObservation& o : t.cameras) {
      if (o.camera_unit != unit) continue;
      ProjectorGridPoint p;
      p.projector_px = t.projector_px.cast<float>();
      p.camera_px = o.camera_px.cast<float>();
      cells.push_back(p);
    }
  }
  return cells;
}

}  // namespace

Status PlanarityOptions::Check() const {
  if (!(threshold_mm > 0.0) || !(plane_inlier_mm > 0.0)) {
    return InvalidArgumentError("planarity: thresholds must be > 0");
  }
  if (outliers_allowed < 0 || !(outlier_fraction >= 0.0 && outlier_fraction < 1.0)) {
    return InvalidArgumentError("planarity: outliers_allowed >= 0, outlier_fraction in [0, 1)");
  }
  if (min_points < 3) return InvalidArgumentError("planarity: min_points must be >= 3");
  if (surface_degree < 0 || surface_degree > 6) {
    return InvalidArgumentError("planarity: surface_degree must be in [0, 6]");
  }
  return OkStatus();
}

Expected<PlanarityProbe> ProbePlanarity(const UnitModel& self,
                                        const std::vector<ProjectorGridPoint>& own_cells,
                                        const PlanarityOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  TriangulationOptions triangulation;
  triangulation.min_angle_deg = 0.5;
  std::vector<Eigen::Vector3d> points;
  points.reserve(own_cells.size());
  for (const ProjectorGridPoint& c : own_cells) {
    TriangulationView views[2];
    views[0].camera = self.camera;
    views[0].camera_from_world = Rigid3d::Identity();
    views[0].observed_px = c.camera_px.cast<double>();
    views[1].camera = self.projector;
    views[1].camera_from_world = self.projector_from_camera;
    views[1].observed_px = c.projector_px.cast<double>();
    Expected<TriangulationReport> point = TriangulatePoint(views, triangulation);
    if (point.ok() && point->rms_px < 10.0) points.push_back(point->point_in_world);
  }
  if (static_cast<int>(points.size()) < options.min_points) {
    return DegenerateError("unit " + std::to_string(self.unit) + ": its camera triangulated " +
                           std::to_string(points.size()) + " of its projector's " +
                           std::to_string(own_cells.size()) + " cells (at least " +
                           std::to_string(options.min_points) + " needed for its plane)");
  }
  PlaneFitOptions fit;
  fit.inlier_threshold_m = options.plane_inlier_mm * 1e-3;
  fit.min_inlier_ratio = 0.3;
  Expected<PlaneFitReport> plane = FitPlaneRansac(points, fit);
  if (!plane.ok()) {
    return DegenerateError("unit " + std::to_string(self.unit) +
                           ": no plane in its footprint: " + plane.status().message());
  }
  PlanarityProbe probe;
  probe.points = static_cast<int>(points.size());
  probe.plane_in_camera = plane->plane.OrientedToward(Eigen::Vector3d::Zero());
  probe.plane_rms_mm = plane->rms_m * 1e3;
  probe.inlier_ratio = plane->inlier_ratio;
  // Heights over the plane, then over a smooth surface fitted to them (the factory models
  // bend a triangulated plane by up to ~20 mm, smoothly; relief stands off it in steps).
  const PlaneFrame frame = MakePlaneFrame(probe);
  const int n = static_cast<int>(points.size());
  std::vector<Eigen::Vector2d> at(n);
  std::vector<double> height(n);
  double extent = 1e-9;
  for (int i = 0; i < n; ++i) {
    at[i] = frame.axes.transpose() * (points[i] - frame.origin);
    height[i] = probe.plane_in_camera.SignedDistance_m(points[i]) * 1e3;
    extent = std::max(extent, at[i].cwiseAbs().maxCoeff());
  }
  const int degree = options.surface_degree;
  const int terms = (degree + 1) * (degree + 2) / 2;
  auto basis = [&](const Eigen::Vector2d& x, double* row) {
    const double u = x.x() / extent, v = x.y() / extent;
    int k = 0;
    for (int d = 0; d <= degree; ++d) {
      for (int a = d; a >= 0; --a) row[k++] = std::pow(u, a) * std::pow(v, d - a);
    }
  };
  Eigen::VectorXd coefficients = Eigen::VectorXd::Zero(terms);
  std::vector<double> residual(height);
  double keep_mm = std::numeric_limits<double>::infinity();
  Eigen::VectorXd row(terms);
  for (int pass = 0; pass < 6; ++pass) {
    Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(terms, terms);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(terms);
    int used = 0;
    for (int i = 0; i < n; ++i) {
      if (std::abs(residual[i]) > keep_mm) continue;
      basis(at[i], row.data());
      normal.selfadjointView<Eigen::Lower>().rankUpdate(row);
      rhs += height[i] * row;
      ++used;
    }
    if (used < terms * 3) break;
    coefficients = normal.selfadjointView<Eigen::Lower>().ldlt().solve(rhs);
    std::vector<double> magnitudes;
    for (int i = 0; i < n; ++i) {
      basis(at[i], row.data());
      residual[i] = height[i] - row.dot(coefficients);
      magnitudes.push_back(std::abs(residual[i]));
    }
    auto mid = magnitudes.begin() + static_cast<std::ptrdiff_t>(magnitudes.size() / 2);
    std::nth_element(magnitudes.begin(), mid, magnitudes.end());
    keep_mm = std::max(options.plane_inlier_mm / 2, 3.0 * 1.4826 * *mid);
  }
  std::vector<double> heights;
  heights.reserve(points.size());
  double sum_sq = 0.0;
  for (int i = 0; i < n; ++i) {
    const double h = std::abs(residual[i]);
    heights.push_back(h);
    if (h <= keep_mm) sum_sq += h * h;
    probe.points_over_threshold += h > options.threshold_mm ? 1 : 0;
  }
  probe.surface_rms_mm = std::sqrt(sum_sq / n);
  const int allowed =
      std::max(options.outliers_allowed,
               static_cast<int>(std::floor(options.outlier_fraction * probe.points)));
  const size_t k = std::min(heights.size() - 1, static_cast<size_t>(allowed));
  std::nth_element(heights.begin(), heights.begin() + static_cast<std::ptrdiff_t>(k), heights.end(),
                   std::greater<double>());
  probe.max_height_mm = heights[k];
  probe.planar = probe.points_over_threshold <= allowed;
  return probe;
}

namespace {

// An observation on its camera's plane (the plane's 2D frame, metres).
struct OnPlaneObservation {
  NodeId camera;
  Eigen::Vector2d x;
};
using PairKey = std::pair<size_t, size_t>;  // (track, pair index within it)

// One solve of the planar path: each camera's plane, the cameras' plane frames tied by 2D
// similarities over the cells they share, the cells' positions on the site's plane, each
// projector posed from its cells, an optional joint refinement with every cell on the plane,
// and the model.
class PlanarSolve {
 public:
  PlanarSolve(NodeId root, const ClusterObservations& observations, const Scene* model,
              const PlanarSolveOptions& options)
      : root_(root), observations_(observations), model_(model), options_(options) {}

  Expected<ClusterSolution> Run();

 private:
  Status FitPlanes();
  void ObserveOnPlanes();
  void ConnectCameras();
  // Every pair of observations of one point by two connected cameras, not dropped.
  template <typename Visit>
  void ForEachPair(const Visit& visit) const;
  Status TieFrames();
  Status PlaceCells();
  Status PoseProjectors();
  void CameraResiduals();
  Status Refine();
  void FindModel();

  NodeId root_;
  const ClusterObservations& observations_;
  const Scene* model_;
  const PlanarSolveOptions& options_;
  ClusterSolution out_;
  StageClock clock_{&out_};
  std::map<NodeId, PlaneFrame> frames_;
  std::vector<std::vector<OnPlaneObservation>> seen_;  // per track
  std::map<std::pair<NodeId, NodeId>, int> shared_;    // cells two cameras share
  std::set<NodeId> connected_;
  std::map<NodeId, int> index_;  // unknown block of each connected camera but the root
  std::map<NodeId, Eigen::Vector4d> similarity_;
  std::set<PairKey> dropped_;
  int pairs_used_ = 0;
  double pair_rms_mm_ = 0.0;
  double scale_ = 1.0;
  std::vector<std::optional<Eigen::Vector3d>> in_site_;  // per track
  size_t site_points_ = 0;
  Rigid3d table_from_site_;
  std::map<NodeId, Rigid3d> projector_from_table_;
  std::map<NodeId, UnitModel> units_;
  BundleReport predicting_;
  std::optional<BundleUncertainty> uncertainty_;
};

Expected<ClusterSolution> PlanarSolve::Run() {
  const double cpu_start = ThreadCpuSeconds();
  clock_ = StageClock(&out_);
  ST_RETURN_IF_ERROR(FitPlanes());
  clock_.Done("planes");
  ObserveOnPlanes();
  ConnectCameras();
  ST_RETURN_IF_ERROR(TieFrames());
  clock_.Done("frames");
  ST_RETURN_IF_ERROR(PlaceCells());
  ST_RETURN_IF_ERROR(PoseProjectors());
  CameraResiduals();
  out_.notes.push_back(
      "planar path: " + std::to_string(connected_.size()) + " camera frames tied by " +
      std::to_string(pairs_used_) + " shared cells (rms " + std::to_string(pair_rms_mm_) + " mm, " +
      std::to_string(dropped_.size()) + " dropped), site scale from the cameras' mean (root's x " +
      std::to_string(1.0 / scale_) + ")");
  clock_.Done("poses");
  units_ = observations_.units;
  if (options_.refine) ST_RETURN_IF_ERROR(Refine());
  if (model_) FindModel();
  for (const auto& [id, pose] : projector_from_table_) {
    out_.calibrations[id] = SolvedUnitCalibration(id, units_.at(id), pose.Inverse(), out_);
  }
  if (uncertainty_) {
    PredictOnTable(predicting_, *uncertainty_, out_.points_in_table_m, &out_.calibrations);
  }
  out_.time_s = ThreadCpuSeconds() - cpu_start;
  out_.bundle.solve_time_s = out_.time_s;
  return std::move(out_);
}

// 1. Each camera's plane.
Status PlanarSolve::FitPlanes() {
  for (const auto& [id, unit] : observations_.units) {
    Expected<PlanarityProbe> probe =
        ProbePlanarity(unit, OwnCells(id, observations_.tracks), options_.planarity);
    if (!probe.ok()) {
      out_.notes.push_back(probe.status().message() + "; its camera is not used");
      continue;
    }
    if (!probe->planar) {
      out_.notes.push_back("unit " + std::to_string(id) + ": " +
                           std::to_string(probe->points_over_threshold) + " of " +
                           std::to_string(probe->points) + " points stand over " +
                           std::to_string(options_.planarity.threshold_mm) +
                           " mm from its surface (rms " + std::to_string(probe->surface_rms_mm) +
                           " mm, max " + std::to_string(probe->max_height_mm) + " mm): not planar");
    }
    frames_[id] = MakePlaneFrame(*probe);
    out_.max_height_mm = std::max(out_.max_height_mm, probe->max_height_mm);
  }
  if (frames_.empty()) return DegenerateError("planar solve: no camera's plane could be fitted");
  if (!frames_.count(root_)) root_ = frames_.begin()->first;
  return OkStatus();
}

// 2. Every observation on its camera's plane, and the cells each pair of cameras shares.
void PlanarSolve::ObserveOnPlanes() {
  seen_.assign(observations_.tracks.size(), {});
  for (size_t t = 0; t < observations_.tracks.size(); ++t) {
    for (const CameraObservation& o : observations_.tracks[t].cameras) {
      auto frame = frames_.find(o.camera_unit);
      if (frame == frames_.end()) continue;
      std::optional<Eigen::Vector2d> x =
          OnPlane(observations_.units.at(o.camera_unit).camera, frame->second, o.camera_px);
      if (x) seen_[t].push_back({o.camera_unit, *x});
    }
    for (size_t i = 0; i < seen_[t].size(); ++i) {
      for (size_t j = i + 1; j < seen_[t].size(); ++j) {
        const NodeId a = std::min(seen_[t][i].camera, seen_[t][j].camera);
        const NodeId b = std::max(seen_[t][i].camera, seen_[t][j].camera);
        if (a != b) ++shared_[{a, b}];
      }
    }
  }
}

// The cameras tied to the root's frame through pairs sharing at least min_shared_cells.
void PlanarSolve::ConnectCameras() {
  connected_ = {root_};
  std::deque<NodeId> queue{root_};
  while (!queue.empty()) {
    const NodeId a = queue.front();
    queue.pop_front();
    for (const auto& [pair, count] : shared_) {
      if (count < options_.min_shared_cells) continue;
      const NodeId other = pair.first == a ? pair.second : pair.second == a ? pair.first : a;
      if (other == a || connected_.count(other)) continue;
      connected_.insert(other);
      queue.push_back(other);
    }
  }
  for (const auto& [id, frame] : frames_) {
    if (!connected_.count(id)) {
      out_.notes.push_back("camera " + std::to_string(id) +
                           ": shares too few cells with the "
                           "cluster's cameras to join its frame; not used");
    }
  }
  for (NodeId id : connected_) {
    if (id != root_) {
      const int k = static_cast<int>(index_.size());
      index_[id] = k;
    }
  }
}

template <typename Visit>
void PlanarSolve::ForEachPair(const Visit& visit) const {
  for (size_t t = 0; t < seen_.size(); ++t) {
    size_t pair = 0;
    for (size_t i = 0; i < seen_[t].size(); ++i) {
      for (size_t j = i + 1; j < seen_[t].size(); ++j, ++pair) {
        const OnPlaneObservation& o1 = seen_[t][i];
        const OnPlaneObservation& o2 = seen_[t][j];
        if (o1.camera == o2.camera || !connected_.count(o1.camera) ||
            !connected_.count(o2.camera) || dropped_.count({t, pair}))
          continue;
        visit(PairKey(t, pair), o1, o2);
      }
    }
  }
}

// The connected cameras' similarities to the root's frame: linear least squares over the pairs
// (r = M1 q1 - M2 q2, the root's q the constant (1, 0, 0, 0)), pairs past 3x the rms (at least
// 2 mm) dropped and solved again, up to three passes; then the site's scale, the geometric mean
// of the cameras' own.
Status PlanarSolve::TieFrames() {
  const int n = 4 * static_cast<int>(index_.size());
  similarity_[root_] = Eigen::Vector4d(1, 0, 0, 0);
  for (const auto& [id, k] : index_) similarity_[id] = Eigen::Vector4d(1, 0, 0, 0);
  for (int pass = 0; pass < 3 && n > 0; ++pass) {
    Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(n, n);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n);
    ForEachPair([&](const PairKey&, const OnPlaneObservation& o1, const OnPlaneObservation& o2) {
      Eigen::Matrix<double, 2, 8> jac = Eigen::Matrix<double, 2, 8>::Zero();
      Eigen::Vector2d constant = Eigen::Vector2d::Zero();
      int blocks[2] = {-1, -1};
      const Eigen::Matrix<double, 2, 4> m1 = SimilarityRows(o1.x), m2 = -SimilarityRows(o2.x);
      if (o1.camera == root_) {
        constant += m1 * Eigen::Vector4d(1, 0, 0, 0);
      } else {
        jac.leftCols<4>() = m1;
        blocks[0] = 4 * index_.at(o1.camera);
      }
      if (o2.camera == root_) {
        constant += m2 * Eigen::Vector4d(1, 0, 0, 0);
      } else {
        jac.rightCols<4>() = m2;
        blocks[1] = 4 * index_.at(o2.camera);
      }
      for (int a = 0; a < 2; ++a) {
        if (blocks[a] < 0) continue;
        const auto ja = jac.middleCols<4>(4 * a);
        rhs.segment<4>(blocks[a]) -= ja.transpose() * constant;
        for (int b = 0; b < 2; ++b) {
          if (blocks[b] < 0) continue;
          normal.block<4, 4>(blocks[a], blocks[b]) += ja.transpose() * jac.middleCols<4>(4 * b);
        }
      }
    });
    Eigen::LDLT<Eigen::MatrixXd> ldlt(normal);
    const Eigen::VectorXd q = ldlt.solve(rhs);
    if (ldlt.info() != Eigen::Success || !q.allFinite()) {
      return DegenerateError("planar solve: the cameras' frames could not be tied");
    }
    for (const auto& [id, k] : index_) similarity_[id] = q.segment<4>(4 * k);
    std::vector<std::pair<PairKey, double>> residuals;
    double sum_sq = 0.0;
    ForEachPair(
        [&](const PairKey& key, const OnPlaneObservation& o1, const OnPlaneObservation& o2) {
          const double r = (SimilarityRows(o1.x) * similarity_.at(o1.camera) -
                            SimilarityRows(o2.x) * similarity_.at(o2.camera))
                               .norm();
          residuals.push_back({key, r});
          sum_sq += r * r;
        });
    pairs_used_ = static_cast<int>(residuals.size());
    pair_rms_mm_ = residuals.empty() ? 0.0 : std::sqrt(sum_sq / residuals.size()) * 1e3;
    const double limit = std::max(3.0 * pair_rms_mm_, 2.0) * 1e-3;
    bool any = false;
    for (const auto& [key, r] : residuals) {
      if (r > limit) {
        dropped_.insert(key);
        any = true;
      }
    }
    if (!any) break;
  }
  double log_scale = 0.0;
  for (const auto& [id, q] : similarity_) log_scale += std::log(q.head<2>().norm());
  scale_ = std::exp(log_scale / static_cast<double>(similarity_.size()));
  for (auto& [id, q] : similarity_) q /= scale_;
  return OkStatus();
}

// 3. Site positions (the mean over the cameras that saw a cell), the table frame.
Status PlanarSolve::PlaceCells() {
  in_site_.assign(observations_.tracks.size(), std::nullopt);
  std::vector<Eigen::Vector3d> all_in_site;
  for (size_t t = 0; t < seen_.size(); ++t) {
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    int count = 0;
    for (const OnPlaneObservation& o : seen_[t]) {
      auto s = similarity_.find(o.camera);
      if (s == similarity_.end()) continue;
      sum += SimilarityRows(o.x) * s->second;
      ++count;
    }
    if (count == 0) continue;
    in_site_[t] = Eigen::Vector3d(sum.x() / count, sum.y() / count, 0.0);
    all_in_site.push_back(*in_site_[t]);
  }
  site_points_ = all_in_site.size();
  const Plane site_plane;  // z = 0, normal +z
  Expected<TableFrameReport> frame =
      BuildTableFrame(site_plane, all_in_site, Eigen::Vector3d(0, 0, 1));
  if (!frame.ok()) return DegenerateError("planar solve: table frame: " + frame.status().message());
  table_from_site_ = frame->table_from_source;
  out_.frame = *frame;
  out_.table_from_world = table_from_site_;
  out_.table_points = static_cast<int>(all_in_site.size());
  for (const Eigen::Vector3d& p : all_in_site)
    out_.points_in_table_m.push_back(table_from_site_ * p);
  double plane_rms_sq = 0.0;
  for (const auto& [id, f] : frames_) plane_rms_sq += f.probe.plane_rms_mm * f.probe.plane_rms_mm;
  out_.table_plane_rms_mm = std::sqrt(plane_rms_sq / static_cast<double>(frames_.size()));
  out_.planar = true;
  for (const auto& [id, f] : frames_) out_.planar &= f.probe.planar;
  return OkStatus();
}

// 4. Each projector's pose from its cells on the table (its factory intrinsics held).
Status PlanarSolve::PoseProjectors() {
  std::map<NodeId, std::pair<std::vector<Eigen::Vector3d>, std::vector<Eigen::Vector2d>>> cells;
  for (size_t t = 0; t < observations_.tracks.size(); ++t) {
    if (!in_site_[t]) continue;
    auto& [points, pixels] = cells[observations_.tracks[t].projector_unit];
    points.push_back(table_from_site_ * *in_site_[t]);
    pixels.push_back(observations_.tracks[t].projector_px);
  }
  out_.bundle.termination = "planar";
  for (const auto& [id, unit] : observations_.units) {
    auto c = cells.find(id);
    if (c == cells.end() || c->second.first.size() < 8) {
      out_.notes.push_back("unit " + std::to_string(id) +
                           ": no camera of the cluster's frame saw enough of its projector; left "
                           "out");
      continue;
    }
    ResectionOptions resection;
    resection.fix_intrinsics = true;
    resection.fix_distortion = true;
    resection.initial_camera = unit.projector;
    resection.loss = ResectionLoss::kHuber;
    resection.loss_scale_px = options_.resection_loss_scale_px;
    resection.estimate_uncertainty = false;
    Expected<ResectionResult> pose =
        EstimateResection(c->second.first, c->second.second, unit.projector.width_px,
                          unit.projector.height_px, resection);
    if (!pose.ok()) {
      out_.notes.push_back("unit " + std::to_string(id) +
                           ": projector pose on the plane: " + pose.status().message());
      continue;
    }
    projector_from_table_[id] = pose->camera_from_world;
    UnitBundleReport& report = out_.bundle.units[id];
    report.projector_observations = static_cast<int>(c->second.first.size());
    report.projector_rms_px = pose->report.final_rms_px;
    report.free_parameters = {"projector pose (intrinsics and distortion: factory)",
                              "camera plane frame (2D similarity)"};
    out_.bundle.iterations += pose->report.iterations;
  }
  if (projector_from_table_.empty()) return DegenerateError("planar solve: no projector was posed");
  out_.bundle.tracks_used = static_cast<int>(site_points_);
  out_.bundle.observations_dropped = static_cast<int>(dropped_.size());
  return OkStatus();
}

// Camera residuals: the cells' table positions through each camera posed by its mount; the
// projectors' rms over all their observations.
void PlanarSolve::CameraResiduals() {
  for (const auto& [id, pose] : projector_from_table_) {
    if (!frames_.count(id)) continue;
    const UnitModel& unit = observations_.units.at(id);
    const Rigid3d camera_from_table = unit.projector_from_camera.Inverse() * pose;
    double sum_sq = 0.0;
    int count = 0;
    for (size_t t = 0; t < observations_.tracks.size(); ++t) {
      if (!in_site_[t]) continue;
      for (const CameraObservation& o : observations_.tracks[t].cameras) {
        if (o.camera_unit != id) continue;
        std::optional<Eigen::Vector2d> px =
            unit.camera.Project(camera_from_table * (table_from_site_ * *in_site_[t]));
        if (!px) continue;
        sum_sq += (*px - o.camera_px).squaredNorm();
        ++count;
      }
    }
    UnitBundleReport& report = out_.bundle.units[id];
    report.camera_observations = count;
    report.camera_rms_px = count ? std::sqrt(sum_sq / count) : 0.0;
  }
  double all_sq = 0.0;
  int all_n = 0;
  for (const auto& [id, r] : out_.bundle.units) {
    all_sq += r.projector_rms_px * r.projector_rms_px * r.projector_observations;
    all_n += r.projector_observations;
  }
  out_.bundle.final_rms_px = all_n ? std::sqrt(all_sq / all_n) : 0.0;
}

// 5. The joint refinement with every cell on the plane z = 0 of the table frame; when it fails
// the plane-induced poses are kept.
Status PlanarSolve::Refine() {
  BundleResult previous;
  previous.units = observations_.units;
  previous.projector_from_world = projector_from_table_;
  BundleWarmStart warm;
  warm.previous = &previous;
  warm.surface_sigma_m = options_.surface_sigma_m;
  for (size_t t = 0; t < observations_.tracks.size(); ++t) {
    if (!in_site_[t] || !projector_from_table_.count(observations_.tracks[t].projector_unit))
      continue;
    warm.surface.push_back({static_cast<int>(previous.points_in_world.size()),
                            Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()});
    previous.points_in_world.push_back(table_from_site_ * *in_site_[t]);
    previous.point_track.push_back(static_cast<int>(t));
  }
  Expected<BundleResult> refined =
      AdjustCluster(observations_, projector_from_table_, root_, options_.bundle, &warm);
  clock_.Done("bundle");
  if (!refined.ok()) {
    out_.notes.push_back("planar refinement: " + refined.status().message() +
                         "; the plane-induced poses are kept");
    return OkStatus();
  }
  const Plane site_plane;  // z = 0, normal +z
  Expected<TableFrameReport> again =
      BuildTableFrame(site_plane, refined->points_in_world, Eigen::Vector3d(0, 0, 1));
  if (!again.ok()) {
    return DegenerateError("planar solve: table frame: " + again.status().message());
  }
  const Rigid3d table_from_world = again->table_from_source;
  out_.frame = *again;
  out_.table_from_world = table_from_world * out_.table_from_world;
  out_.points_in_table_m.clear();
  for (const Eigen::Vector3d& p : refined->points_in_world)
    out_.points_in_table_m.push_back(table_from_world * p);
  out_.table_points = static_cast<int>(out_.points_in_table_m.size());
  units_ = refined->units;
  for (auto& [id, pose] : projector_from_table_) {
    if (refined->projector_from_world.count(id))
      pose = refined->projector_from_world.at(id) * table_from_world.Inverse();
  }
  out_.bundle = refined->report;
  out_.bundle.termination = "planar, refined: " + refined->report.termination;
  predicting_ = refined->report;
  uncertainty_ = refined->uncertainty;
  return OkStatus();
}

// 6. The model: its best placement and what each building shows there.
void PlanarSolve::FindModel() {
  ModelMatcher matcher(*model_, options_.model);
  Expected<std::vector<ModelRegistration>> candidates =
      matcher.RegisterCandidates(out_.points_in_table_m, 1);
  if (!candidates.ok()) {
    out_.notes.push_back(candidates.status().message());
  } else {
    out_.model = candidates->front();
    Expected<ModelChangeReport> changes = DetectModelChanges(
        *model_, out_.points_in_table_m, out_.model->table_from_model, options_.changes);
    if (changes.ok()) {
      out_.changes = std::move(*changes);
    } else {
      out_.notes.push_back("change report: " + changes.status().message());
    }
  }
  clock_.Done("model");
}

}  // namespace

Expected<ClusterSolution> SolvePlanarCluster(NodeId root, const ClusterObservations& observations,
                                             const Scene* model,
                                             const PlanarSolveOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  return PlanarSolve(root, observations, model, options).Run();
}

Status PlanarSolveOptions::Check() const {
  ST_RETURN_IF_ERROR(planarity.Check());
  ST_RETURN_IF_ERROR(model.Check());
  ST_RETURN_IF_ERROR(changes.Check());
  ST_RETURN_IF_ERROR(bundle.Check());
  if (min_shared_cells < 3 || !(resection_loss_scale_px > 0.0) || !(surface_sigma_m > 0.0)) {
    return InvalidArgumentError(
        "planar solve: min_shared_cells >= 3; resection loss scale and surface sigma > 0");
  }
  return OkStatus();
}

}  // namespace sandtable::node
