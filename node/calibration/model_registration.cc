#include "node/calibration/model_registration.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace sandtable::node {
namespace {

constexpr double kPi = 3.14159265358979323846;
// The smallest pairing gate of the ICP's last iterations (m): a few times the scan's noise.
constexpr double kTightGate_m = 0.0015;
constexpr double kIcpDamping = 1e-6;
// A scan (or model) with less than this fraction of its points above structure_height_m is flat.
constexpr double kFlatFraction = 0.005;
// The flat path: cells of the outline masks, and the least part of the model's top the scan
// must cover for its outline to place the model.
constexpr double kOutlineCell_m = 0.004;
constexpr double kMinOutlineCoverage = 0.9;
// Principal axes whose second moments differ by less than this ratio leave the yaw open.
constexpr double kMinAxisRatio = 1.05;
// Placements kept for the caller to choose from: those whose ICP pairs reach this fraction of
// the best one's (a city's regular blocks fit the table equally well at several places).
constexpr double kCandidateInlierRatio = 0.9;
// A relief (heights' scale over the plan's) this many standard errors from 1 is real.
constexpr double kReliefSignificance = 3.0;
// The relief maps' window (cells each side, 10 x 2 cm): what stands above the mean height of the
// 42 x 42 cm around it.
constexpr int kReliefWindowCells = 10;
// What a placement found on those maps must fit (of the scan's points within icp_max_distance_m).
constexpr double kReliefMinInlierFraction = 0.85;

// model_from_table as s R p + t.
// model = s R (H p) + t, where H stretches the scan's x and y (table frame) by `a` about
// `pivot` and leaves z: the relief's scale against the plan's (1 for a similarity).
struct Similarity {
  double s = 1.0;
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double a = 1.0;
  Eigen::Vector3d pivot = Eigen::Vector3d::Zero();
  Eigen::Vector3d Stretch(const Eigen::Vector3d& p) const {
    if (a == 1.0) return p;
    return {pivot.x() + a * (p.x() - pivot.x()), pivot.y() + a * (p.y() - pivot.y()), p.z()};
  }
  Eigen::Vector3d Apply(const Eigen::Vector3d& p) const { return s * (r * Stretch(p)) + t; }
};

struct Grid {
  double min_x = 0, min_y = 0, cell = 0;
  int width = 0, height = 0;
  cv::Mat value;  // CV_32F: +1 structure, -1 table, 0 unknown
};

// Highest z per cell -> +1 / -1 / 0. With `relief_window` > 0 a cell's height is taken over the
// mean of the known cells within that many cells around it (a high-pass: any plane, such as a
// table frame tilted against the model's, leaves no trace away from the map's edges), so the
// classes are "stands above its surroundings" (+1) or not (-1).
// The highest z per cell of `points` turned by `rotation` (-inf where a cell has none), on a
// grid of `cell` from the points' smallest x and y (set in *min_x, *min_y).
cv::Mat TopHeights(std::span<const Eigen::Vector3d> points, const Eigen::Matrix3d& rotation,
                   double cell, double* min_x, double* min_y) {
  *min_x = *min_y = std::numeric_limits<double>::infinity();
  double max_x = -std::numeric_limits<double>::infinity(), max_y = max_x;
  for (const Eigen::Vector3d& p0 : points) {
    const Eigen::Vector3d p = rotation * p0;
    *min_x = std::min(*min_x, p.x());
    *min_y = std::min(*min_y, p.y());
    max_x = std::max(max_x, p.x());
    max_y = std::max(max_y, p.y());
  }
  const int width = static_cast<int>(std::floor((max_x - *min_x) / cell)) + 1;
  const int height = static_cast<int>(std::floor((max_y - *min_y) / cell)) + 1;
  cv::Mat top(height, width, CV_32F, cv::Scalar(-std::numeric_limits<float>::infinity()));
  for (const Eigen::Vector3d& p0 : points) {
    const Eigen::Vector3d p = rotation * p0;
    const int i = std::clamp(static_cast<int>((p.x() - *min_x) / cell), 0, width - 1);
    const int j = std::clamp(static_cast<int>((p.y() - *min_y) / cell), 0, height - 1);
    float& v = top.at<float>(j, i);
    v = std::max(v, static_cast<float>(p.z()));
  }
  return top;
}

Grid HeightGrid(std::span<const Eigen::Vector3d> points, const Eigen::Matrix3d& rotation,
                double cell, double structure_height, int relief_window = 0) {
  Grid g;
  g.cell = cell;
  const cv::Mat top = TopHeights(points, rotation, cell, &g.min_x, &g.min_y);
  g.width = top.cols;
  g.height = top.rows;
  const cv::Mat known = top != -std::numeric_limits<float>::infinity();  // CV_8U 255/0
  cv::Mat ground(g.height, g.width, CV_32F, cv::Scalar(0));
  if (relief_window > 0) {
    cv::Mat heights(g.height, g.width, CV_32F, cv::Scalar(0)), weights;
    top.copyTo(heights, known);
    known.convertTo(weights, CV_32F, 1.0 / 255.0);
    const cv::Size box(2 * relief_window + 1, 2 * relief_window + 1);
    cv::Mat sum_h, sum_w;
    cv::boxFilter(heights, sum_h, CV_32F, box, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::boxFilter(weights, sum_w, CV_32F, box, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::divide(sum_h, cv::max(sum_w, 1e-6), ground);
  }
  g.value = cv::Mat(g.height, g.width, CV_32F, cv::Scalar(0));
  for (int j = 0; j < g.height; ++j) {
    for (int i = 0; i < g.width; ++i) {
      if (!known.at<uint8_t>(j, i)) continue;
      const float z = top.at<float>(j, i) - ground.at<float>(j, i);
      g.value.at<float>(j, i) = z > structure_height ? 1.0f : -1.0f;
    }
  }
  return g;
}

struct Candidate {
  double score = 0;
  double yaw_rad = 0;
  Similarity model_from_table;
};

// The model's top surface per coarse cell (NaN where it has none), for levelling a candidate.
struct TopMap {
  double min_x = 0, min_y = 0, cell = 0;
  cv::Mat z;  // CV_32F
  float At(double x, double y) const {
    const int i = static_cast<int>(std::floor((x - min_x) / cell));
    const int j = static_cast<int>(std::floor((y - min_y) / cell));
    if (i < 0 || j < 0 || i >= z.cols || j >= z.rows)
      return std::numeric_limits<float>::quiet_NaN();
    return z.at<float>(j, i);
  }
};

TopMap ModelTop(std::span<const Eigen::Vector3d> points, double cell) {
  TopMap m;
  m.cell = cell;
  m.z = TopHeights(points, Eigen::Matrix3d::Identity(), cell, &m.min_x, &m.min_y);
  m.z.setTo(std::numeric_limits<float>::quiet_NaN(),
            m.z == -std::numeric_limits<float>::infinity());
  return m;
}

// A candidate levelled: where the scan's table plane is not the model's (a terrain whose large
// slope the plane fit took for the table), the model's top minus the scan's heights at the
// candidate's x, y and yaw is a plane. Fitted robustly (least squares, then again without the
// points over 3 median deviations: walls and what the model lacks), it tilts and lifts the
// candidate. nullopt when under 50 points compare or the plane is negligible.
std::optional<Similarity> Levelled(const Similarity& x, std::span<const Eigen::Vector3d> scan,
                                   const TopMap& top) {
  constexpr double kNegligibleTilt_rad = 0.1 * kPi / 180.0;
  constexpr double kNegligibleLift_m = 0.002;
  std::vector<Eigen::Vector3d> rows;  // model x, model y, difference
  for (const Eigen::Vector3d& p : scan) {
    const Eigen::Vector3d m = x.Apply(p);
    const float z = top.At(m.x(), m.y());
    if (std::isnan(z)) continue;
    rows.emplace_back(m.x(), m.y(), static_cast<double>(z) - m.z());
  }
  if (rows.size() < 50) return std::nullopt;
  Eigen::Vector3d plane = Eigen::Vector3d::Zero();  // difference = a x + b y + c
  std::vector<bool> keep(rows.size(), true);
  for (int pass = 0; pass < 3; ++pass) {
    Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
    Eigen::Vector3d atb = Eigen::Vector3d::Zero();
    int used = 0;
    for (size_t i = 0; i < rows.size(); ++i) {
      if (!keep[i]) continue;
      const Eigen::Vector3d a(rows[i].x(), rows[i].y(), 1.0);
      ata += a * a.transpose();
      atb += a * rows[i].z();
      ++used;
    }
    if (used < 50) return std::nullopt;
    plane = ata.ldlt().solve(atb);
    std::vector<double> residuals;
    for (const Eigen::Vector3d& r : rows) {
      residuals.push_back(std::abs(r.z() - plane.dot(Eigen::Vector3d(r.x(), r.y(), 1.0))));
    }
    std::vector<double> sorted = residuals;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double gate = std::max(0.001, 3.0 * 1.4826 * sorted[sorted.size() / 2]);
    for (size_t i = 0; i < rows.size(); ++i) keep[i] = residuals[i] <= gate;
  }
  if (!plane.allFinite()) return std::nullopt;
  const double tilt = std::atan(std::hypot(plane.x(), plane.y()));
  if (tilt < kNegligibleTilt_rad && std::abs(plane.z()) < kNegligibleLift_m) return std::nullopt;
  // z + a x + b y + c: a turn about y by -atan(a), about x by atan(b), then a lift by c.
  const Eigen::Matrix3d level = (Eigen::AngleAxisd(std::atan(plane.y()), Eigen::Vector3d::UnitX()) *
                                 Eigen::AngleAxisd(-std::atan(plane.x()), Eigen::Vector3d::UnitY()))
                                    .toRotationMatrix();
  Similarity out = x;
  out.r = level * x.r;
  out.t = level * x.t + Eigen::Vector3d(0, 0, plane.z());
  return out;
}

}  // namespace

Status ModelRegistrationOptions::Check() const {
  if (!(structure_height_m > 0) || !(coarse_cell_m > 0) || !(coarse_yaw_step_deg > 0) ||
      !(sample_spacing_m > 0) || !(icp_max_distance_m > 0)) {
    return InvalidArgumentError("model registration: heights, cells, steps must be > 0");
  }
  if (coarse_candidates < 1 || icp_iterations < 1 || min_points < 3 ||
      !(min_inlier_fraction > 0 && min_inlier_fraction <= 1)) {
    return InvalidArgumentError("model registration: counts >= 1, inlier fraction in (0, 1]");
  }
  return OkStatus();
}

ModelSurface SampleModelSurface(const Scene& model, double spacing_m) {
  ModelSurface out;
  for (int t = 0; t < model.NumTriangles(); ++t) {
    const Eigen::Vector3i& tri = model.triangles[t];
    const Eigen::Vector3d a = model.positions_in_table_m[tri[0]].cast<double>();
    const Eigen::Vector3d b = model.positions_in_table_m[tri[1]].cast<double>();
    const Eigen::Vector3d c = model.positions_in_table_m[tri[2]].cast<double>();
    const Eigen::Vector3d n = model.FaceNormal(t);
    if (n.squaredNorm() < 0.5) continue;  // degenerate
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    // The table top (z = 0, facing up) is one plane: every sample of it gives ICP the same
    // plane, so it is sampled 3x coarser (the bulk of the model's area, and of the k-d tree).
    const bool table_top = std::abs(a.z()) < 1e-4 && std::abs(b.z()) < 1e-4 &&
                           std::abs(c.z()) < 1e-4 && std::abs(n.z()) > 0.999;
    const double spacing = table_top ? 3.0 * spacing_m : spacing_m;
    const int k = std::max(1, static_cast<int>(std::ceil(longest / spacing)));
    // Centroids of the k^2 sub-triangles of a regular subdivision.
    for (int i = 0; i < k; ++i) {
      for (int j = 0; i + j < k; ++j) {
        for (int up = 0; up < 2; ++up) {
          if (up == 1 && i + j + 1 >= k) continue;
          const double u = up == 0 ? (i + 1.0 / 3.0) / k : (i + 2.0 / 3.0) / k;
          const double v = up == 0 ? (j + 1.0 / 3.0) / k : (j + 2.0 / 3.0) / k;
          out.points_m.push_back(a + u * (b - a) + v * (c - a));
          out.normals.push_back(n);
          out.triangle.push_back(t);
        }
      }
    }
  }
  return out;
}

ModelMatcher::ModelMatcher(const Scene& model, const ModelRegistrationOptions& options)
    : options_(options),
      surface_(SampleModelSurface(model, options.sample_spacing_m)),
      tree_(std::make_unique<PointTree>(&surface_.points_m)) {}

ModelMatcher::~ModelMatcher() = default;

bool ModelMatcher::SurfacePlaneNear(const Eigen::Vector3d& point_in_model_m, double max_distance_m,
                                    Eigen::Vector3d* point_on_plane_m,
                                    Eigen::Vector3d* normal) const {
  constexpr size_t kK = 8;
  if (surface_.points_m.size() < kK) return false;
  size_t index[kK];
  double d2[kK];
  const size_t found = tree_->Nearest(point_in_model_m, kK, index, d2);
  if (found < kK || d2[0] > max_distance_m * max_distance_m) return false;
  const Eigen::Vector3d& n0 = surface_.normals[index[0]];
  for (size_t i = 1; i < found; ++i) {
    if (std::abs(surface_.normals[index[i]].dot(n0)) < 0.999) return false;
  }
  *point_on_plane_m = surface_.points_m[index[0]];
  *normal = n0;
  return true;
}

namespace {

// At most this many scan points in an ICP (every k-th): 5 000 points already pin the placement
// to a few hundredths of a mm (docs/calibration.md); more only cost time.
constexpr int kMaxIcpPoints = 5000;

std::vector<Eigen::Vector3d> Subsample(std::span<const Eigen::Vector3d> scan, int at_most) {
  const int stride = std::max(1, static_cast<int>((scan.size() + at_most - 1) / at_most));
  std::vector<Eigen::Vector3d> out;
  for (size_t i = 0; i < scan.size(); i += stride) out.push_back(scan[i]);
  return out;
}

struct IcpOutcome {
  Similarity model_from_table;
  double rms_m = 0;
  int inliers = 0;
  // With the relief free: its standard error from the last step's normal equations (the
  // residuals' rms as their sigma).
  double relief_sigma = 0;
};

// The registration an ICP outcome gives: table = (1/s) R^T (model - t), i.e. the rigid part of
// the inverse with the scale taken out.
ModelRegistration FromIcp(const IcpOutcome& icp, int points_fitted) {
  ModelRegistration out;
  // The plan's scale: a scan whose relief reads taller or flatter than its plan (a downward
  // rig's focal length traded against its distance) is rescaled by its plan, which is what
  // places each projector's image on the table.
  const Similarity& x = icp.model_from_table;
  out.scale = 1.0 / (x.s * x.a);
  out.relief_scale = x.a;
  // The similarity of the plan's scale that agrees with the fit at the pivot.
  const Eigen::Vector3d t = x.t + x.s * (1.0 - x.a) * (x.r * x.pivot);
  const Eigen::Matrix3d rt = x.r.transpose();
  out.table_from_model = Rigid3d(rt, -rt * t);
  out.rms_m = icp.rms_m;
  out.inliers = icp.inliers;
  out.points = points_fitted;
  return out;
}

}  // namespace

static IcpOutcome RunIcp(const PointTree& tree, const ModelSurface& surface,
                         std::span<const Eigen::Vector3d> scan, Similarity x, bool scale_free,
                         int iterations, double final_distance_m, bool plan_free = false) {
  IcpOutcome out;
  const int n = static_cast<int>(scan.size());
  for (int it = 0; it < iterations; ++it) {
    // Pairing: the nearest sample within `gate` (wide for the first iterations: the coarse
    // grid's resolution; then the final distance; samples are up to ~0.7 x the spacing apart,
    // 3x that on the table top). After that, pairs whose point-to-plane distance exceeds 3x
    // the last rms (at least kTightGate_m) are dropped too: scan points that bridge an edge (a
    // roof edge to the table) are not the model's surface.
    const double gate =
        it < 4 ? 3.0 * final_distance_m : (it < 8 ? 1.5 * final_distance_m : final_distance_m);
    double plane_gate = std::numeric_limits<double>::infinity();
    if (it >= 8 && std::isfinite(out.rms_m)) {
      plane_gate = std::max(kTightGate_m, 3.0 * out.rms_m);
    }
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (int i = 0; i < n; ++i) centre += x.Apply(scan[i]);
    centre /= std::max(1, n);
    if (it == 0 && plan_free) {
      x.pivot = Eigen::Vector3d::Zero();
      for (int i = 0; i < n; ++i) x.pivot += scan[i];
      x.pivot /= std::max(1, n);
    }
    const Eigen::Matrix3d sr = x.s * x.r;
    Eigen::Matrix<double, 8, 8> a = Eigen::Matrix<double, 8, 8>::Zero();
    Eigen::Matrix<double, 8, 1> b = Eigen::Matrix<double, 8, 1>::Zero();
    double sum_sq = 0;
    int inliers = 0;
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d p = x.Apply(scan[i]);
      double d2 = 0;
      const size_t k = tree.Nearest(p, &d2);
      if (d2 > gate * gate) continue;
      const Eigen::Vector3d& q = surface.points_m[k];
      const Eigen::Vector3d& nq = surface.normals[k];
      const double r = nq.dot(p - q);
      if (std::abs(r) > plane_gate) continue;
      Eigen::Matrix<double, 8, 1> j;
      j.head<3>() = p.cross(nq);
      j.segment<3>(3) = nq;
      j[6] = scale_free ? nq.dot(p - centre) : 0.0;
      if (plan_free) {
        const Eigen::Vector3d h = x.Stretch(scan[i]) - x.pivot;
        j[7] = nq.dot(sr * Eigen::Vector3d(h.x(), h.y(), 0.0));
      } else {
        j[7] = 0.0;
      }
      a += j * j.transpose();
      b -= j * r;
      sum_sq += r * r;
      ++inliers;
    }
    out.inliers = inliers;
    out.rms_m = inliers ? std::sqrt(sum_sq / inliers) : std::numeric_limits<double>::infinity();
    if (inliers < 10) break;
    if (!scale_free) a(6, 6) = 1.0;
    if (!plan_free) a(7, 7) = 1.0;
    if (plan_free) {
      const Eigen::Matrix<double, 8, 8> inverse = a.inverse();
      out.relief_sigma = std::sqrt(std::max(0.0, inverse(7, 7)) * sum_sq / inliers);
    }
    // Damping: a direction the points do not determine (x, y, yaw and scale on a flat scan)
    // stays where it is instead of taking a step of noise over nothing (a scan of a flat table
    // sent the scale to -1e163 without it).
    a.diagonal().array() += kIcpDamping * inliers;
    const Eigen::Matrix<double, 8, 1> d = a.ldlt().solve(b);
    if (!d.allFinite()) break;
    const Eigen::Vector3d w = d.head<3>();
    const Eigen::Matrix3d rw = w.norm() > 0
                                   ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix()
                                   : Eigen::Matrix3d::Identity();
    const double ds = scale_free ? d[6] : 0.0;
    x.s *= (1.0 + ds);
    if (plan_free) x.a *= (1.0 + d[7]);
    x.r = rw * x.r;
    x.t = rw * ((1.0 + ds) * (x.t - centre) + centre) + d.segment<3>(3);
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(x.r, Eigen::ComputeFullU | Eigen::ComputeFullV);
    x.r = svd.matrixU() * svd.matrixV().transpose();
    // Converged: the step moves no point by more than ~1e-8 m (rotation in rad, metres).
    if (it >= 8 && d.head<6>().norm() < 1e-7 && std::abs(d[6]) < 1e-7 && std::abs(d[7]) < 1e-7) {
      break;
    }
  }
  out.model_from_table = x;
  return out;
}

// The scale-free fit: with scale_from_plan, the relief free too, kept only where it differs
// from the plan's scale by more than kReliefSignificance standard errors (else the one scale
// of the similarity, which every point sets, is the better estimate; the plan's alone rests
// on the few walls a camera looking down sees).
static IcpOutcome RunScaleFreeIcp(const PointTree& tree, const ModelSurface& surface,
                                  std::span<const Eigen::Vector3d> scan, const Similarity& x,
                                  bool scale_free, bool scale_from_plan, int iterations,
                                  double final_distance_m) {
  if (scale_free && scale_from_plan) {
    IcpOutcome relief =
        RunIcp(tree, surface, scan, x, true, iterations, final_distance_m, /*plan_free=*/true);
    if (std::abs(relief.model_from_table.a - 1.0) > kReliefSignificance * relief.relief_sigma) {
      return relief;
    }
  }
  return RunIcp(tree, surface, scan, x, scale_free, iterations, final_distance_m);
}

Expected<ModelRegistration> ModelMatcher::Refine(std::span<const Eigen::Vector3d> scan,
                                                 const Rigid3d& table_from_model,
                                                 bool scale_free) const {
  if (static_cast<int>(scan.size()) < options_.min_points) {
    return DegenerateError("model registration: " + std::to_string(scan.size()) +
                           " scanned points (at least " + std::to_string(options_.min_points) +
                           ")");
  }
  const Rigid3d model_from_table = table_from_model.Inverse();
  Similarity x;
  x.r = model_from_table.RotationMatrix();
  x.t = model_from_table.translation;
  const std::vector<Eigen::Vector3d> points = Subsample(scan, kMaxIcpPoints);
  IcpOutcome icp =
      RunScaleFreeIcp(*tree_, surface_, points, x, scale_free, options_.scale_from_plan,
                      options_.icp_iterations, options_.icp_max_distance_m);
  return FromIcp(icp, static_cast<int>(points.size()));
}

namespace {

// Area moments of a mask: centroid and the angle of its major axis.
struct Moments {
  double area_m2 = 0;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double axis_rad = 0;
  double axis_ratio = 1;  // major / minor second moment
};

Moments MaskMoments(const cv::Mat& mask, double min_x, double min_y, double cell) {
  Moments m;
  double n = 0, sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
  for (int j = 0; j < mask.rows; ++j) {
    const uint8_t* row = mask.ptr<uint8_t>(j);
    for (int i = 0; i < mask.cols; ++i) {
      if (!row[i]) continue;
      const double x = min_x + (i + 0.5) * cell, y = min_y + (j + 0.5) * cell;
      n += 1;
      sx += x;
      sy += y;
      sxx += x * x;
      syy += y * y;
      sxy += x * y;
    }
  }
  if (n == 0) return m;
  m.area_m2 = n * cell * cell;
  m.centre = {sx / n, sy / n};
  Eigen::Matrix2d c;
  c << sxx / n - m.centre.x() * m.centre.x(), sxy / n - m.centre.x() * m.centre.y(),
      sxy / n - m.centre.x() * m.centre.y(), syy / n - m.centre.y() * m.centre.y();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(c);
  const Eigen::Vector2d major = eig.eigenvectors().col(1);
  m.axis_rad = std::atan2(major.y(), major.x());
  m.axis_ratio = eig.eigenvalues()(0) > 0 ? eig.eigenvalues()(1) / eig.eigenvalues()(0) : 1e9;
  return m;
}

// Points (x, y) into a mask of `cell`, gaps up to `close_m` closed.
cv::Mat PointMask(const std::vector<Eigen::Vector2d>& xy, double min_x, double min_y, int w, int h,
                  double cell, double close_m) {
  cv::Mat mask(h, w, CV_8U, cv::Scalar(0));
  for (const Eigen::Vector2d& p : xy) {
    const int i = static_cast<int>((p.x() - min_x) / cell);
    const int j = static_cast<int>((p.y() - min_y) / cell);
    if (i >= 0 && j >= 0 && i < w && j < h) mask.at<uint8_t>(j, i) = 255;
  }
  const int r = std::max(1, static_cast<int>(std::ceil(close_m / cell)));
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1));
  cv::morphologyEx(mask, mask, cv::MORPH_CLOSE, disc);
  return mask;
}

}  // namespace

Expected<ModelRegistration> ModelMatcher::RegisterByOutline(
    std::span<const Eigen::Vector3d> scan) const {
  // The model's top: its samples facing up (the table top sampled 3x coarser: closed like the
  // scan's points).
  std::vector<Eigen::Vector2d> model_xy, scan_xy;
  for (size_t i = 0; i < surface_.points_m.size(); ++i) {
    if (surface_.normals[i].z() > 0.9) model_xy.push_back(surface_.points_m[i].head<2>());
  }
  for (const Eigen::Vector3d& p : scan) scan_xy.push_back(p.head<2>());
  // The scan's spacing: median distance to the nearest of a few hundred points' neighbours.
  std::vector<double> nearest;
  const size_t stride = std::max<size_t>(1, scan_xy.size() / 300);
  for (size_t i = 0; i < scan_xy.size(); i += stride) {
    double best = std::numeric_limits<double>::infinity();
    for (size_t j = 0; j < scan_xy.size(); ++j) {
      if (j != i) best = std::min(best, (scan_xy[i] - scan_xy[j]).squaredNorm());
    }
    nearest.push_back(std::sqrt(best));
  }
  std::nth_element(nearest.begin(),
                   nearest.begin() + static_cast<std::ptrdiff_t>(nearest.size() / 2),
                   nearest.end());
  const double spacing = nearest[nearest.size() / 2];
  const double model_spacing = 3.0 * options_.sample_spacing_m;
  auto moments_of = [&](const std::vector<Eigen::Vector2d>& xy, double close_m) {
    Eigen::AlignedBox2d box;
    for (const Eigen::Vector2d& p : xy) box.extend(p);
    const double margin = 2 * close_m + kOutlineCell_m;
    const double min_x = box.min().x() - margin, min_y = box.min().y() - margin;
    const int w = static_cast<int>(std::ceil((box.sizes().x() + 2 * margin) / kOutlineCell_m));
    const int h = static_cast<int>(std::ceil((box.sizes().y() + 2 * margin) / kOutlineCell_m));
    return MaskMoments(PointMask(xy, min_x, min_y, w, h, kOutlineCell_m, close_m), min_x, min_y,
                       kOutlineCell_m);
  };
  const Moments model = moments_of(model_xy, 1.5 * model_spacing);
  const Moments seen = moments_of(scan_xy, 1.5 * spacing);
  const double coverage = model.area_m2 > 0 ? seen.area_m2 / model.area_m2 : 0.0;
  if (coverage < kMinOutlineCoverage) {
    return DegenerateError("model registration: the model is flat and the scan covers " +
                           std::to_string(static_cast<int>(coverage * 100)) +
                           " % of its top: its outline cannot place it (at least " +
                           std::to_string(static_cast<int>(kMinOutlineCoverage * 100)) + " %)");
  }
  if (model.axis_ratio < kMinAxisRatio || seen.axis_ratio < kMinAxisRatio) {
    return DegenerateError(
        "model registration: the model is flat and its outline has no long axis (a disc or a "
        "square): its turn about the vertical cannot be found");
  }
  // model = R (scan) + t with R turning the scan's axis onto the model's; of the two
  // directions of an axis, the one that puts the scan's points on the model's top.
  ModelRegistration best;
  double best_inside = -1;
  for (int flip = 0; flip < 2; ++flip) {
    const double yaw = model.axis_rad - seen.axis_rad + flip * kPi;
    const Eigen::Matrix3d r = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Eigen::Vector2d t2 = model.centre - r.topLeftCorner<2, 2>() * seen.centre;
    const Eigen::Vector3d t(t2.x(), t2.y(), 0.0);
    int inside = 0;
    double sum_sq = 0;
    const size_t step = std::max<size_t>(1, scan.size() / 2000);
    int tried = 0;
    for (size_t i = 0; i < scan.size(); i += step) {
      const Eigen::Vector3d p = r * scan[i] + t;
      double d2 = 0;
      const size_t k = tree_->Nearest(p, &d2);
      ++tried;
      if (d2 > model_spacing * model_spacing) continue;
      ++inside;
      const double dz = surface_.normals[k].dot(p - surface_.points_m[k]);
      sum_sq += dz * dz;
    }
    if (inside > best_inside) {
      best_inside = inside;
      const Eigen::Matrix3d rt = r.transpose();
      best.table_from_model = Rigid3d(rt, -rt * t);
      best.rms_m = inside ? std::sqrt(sum_sq / inside) : 0.0;
      best.inliers = inside;
      best.points = tried;
    }
  }
  best.scale = 1.0;  // a plane says nothing of the scale
  best.coarse_score = coverage;
  best.candidates_tried = 2;
  best.structure_fraction = 0.0;
  best.by_outline = true;
  return best;
}

// Step 2: the best placements in x, y and yaw of the scan's height map on the model's, one per
// distinct yaw (at most coarse_candidates), best first.
static std::vector<Candidate> CoarseCandidates(const ModelSurface& surface,
                                               const ModelRegistrationOptions& options,
                                               std::span<const Eigen::Vector3d> scan,
                                               int relief_window) {
  const Grid model_grid =
      HeightGrid(surface.points_m, Eigen::Matrix3d::Identity(), options.coarse_cell_m,
                 options.structure_height_m, relief_window);
  // FFT of the model map, padded for every scan map (sizes bounded by the two extents).
  const int pad_w = cv::getOptimalDFTSize(2 * model_grid.width + 8);
  const int pad_h = cv::getOptimalDFTSize(2 * model_grid.height + 8);
  cv::Mat model_padded(pad_h, pad_w, CV_32F, cv::Scalar(0));
  model_grid.value.copyTo(model_padded(cv::Rect(0, 0, model_grid.width, model_grid.height)));
  cv::Mat model_spectrum;
  cv::dft(model_padded, model_spectrum, cv::DFT_COMPLEX_OUTPUT);

  std::vector<Candidate> per_yaw;
  const int steps = std::max(1, static_cast<int>(std::round(360.0 / options.coarse_yaw_step_deg)));
  for (int s = 0; s < steps; ++s) {
    const double yaw = 2.0 * kPi * s / steps;
    const Eigen::Matrix3d rz = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Grid scan_grid =
        HeightGrid(scan, rz, options.coarse_cell_m, options.structure_height_m, relief_window);
    if (scan_grid.width > pad_w || scan_grid.height > pad_h) continue;
    cv::Mat scan_padded(pad_h, pad_w, CV_32F, cv::Scalar(0));
    scan_grid.value.copyTo(scan_padded(cv::Rect(0, 0, scan_grid.width, scan_grid.height)));
    cv::Mat scan_spectrum, product, correlation;
    cv::dft(scan_padded, scan_spectrum, cv::DFT_COMPLEX_OUTPUT);
    cv::mulSpectrums(model_spectrum, scan_spectrum, product, 0, /*conjB=*/true);
    cv::idft(product, correlation, cv::DFT_REAL_OUTPUT | cv::DFT_SCALE);
    double best = 0;
    cv::Point at;
    cv::minMaxLoc(correlation, nullptr, &best, nullptr, &at);
    // Index k (wrapped): model cell = scan cell + k.
    const int kx = at.x > pad_w / 2 ? at.x - pad_w : at.x;
    const int ky = at.y > pad_h / 2 ? at.y - pad_h : at.y;
    Candidate c;
    c.score = best / std::max(1.0, cv::countNonZero(scan_grid.value) * 1.0);
    c.yaw_rad = yaw;
    c.model_from_table.r = rz;
    // Cell centres: scan cell i covers [min + i c, min + (i+1) c); model cell i + k.
    c.model_from_table.t =
        Eigen::Vector3d(model_grid.min_x - scan_grid.min_x + kx * options.coarse_cell_m,
                        model_grid.min_y - scan_grid.min_y + ky * options.coarse_cell_m, 0.0);
    per_yaw.push_back(c);
  }
  std::sort(per_yaw.begin(), per_yaw.end(),
            [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  std::vector<Candidate> chosen;
  for (const Candidate& c : per_yaw) {
    bool near = false;
    for (const Candidate& k : chosen) {
      double d = std::abs(c.yaw_rad - k.yaw_rad);
      d = std::min(d, 2 * kPi - d);
      near |= d < 2.5 * options.coarse_yaw_step_deg * kPi / 180.0;
    }
    if (!near) chosen.push_back(c);
    if (static_cast<int>(chosen.size()) >= options.coarse_candidates) break;
  }
  return chosen;
}

Expected<std::vector<ModelRegistration>> ModelMatcher::RegisterCandidates(
    std::span<const Eigen::Vector3d> scan, int max_candidates) const {
  ST_RETURN_IF_ERROR(options_.Check());
  if (max_candidates < 1) return InvalidArgumentError("model registration: max_candidates < 1");
  const int n = static_cast<int>(scan.size());
  if (n < options_.min_points) {
    return DegenerateError("model registration: " + std::to_string(n) +
                           " scanned points (at least " + std::to_string(options_.min_points) +
                           ")");
  }
  if (surface_.points_m.empty()) return DegenerateError("model registration: the model is empty");
  int structure = 0;
  for (const Eigen::Vector3d& p : scan) structure += p.z() > options_.structure_height_m;
  int model_structure = 0;
  for (const Eigen::Vector3d& p : surface_.points_m) {
    model_structure += p.z() > options_.structure_height_m;
  }
  const bool flat_scan = structure < kFlatFraction * n;
  const bool flat_model =
      model_structure < kFlatFraction * static_cast<double>(surface_.points_m.size());
  if (flat_scan && !flat_model) {
    return DegenerateError("model registration: the scan shows nothing above " +
                           std::to_string(options_.structure_height_m * 1e3) +
                           " mm but the model has buildings: nothing to place them by");
  }
  if (flat_scan && flat_model) {
    Expected<ModelRegistration> outline = RegisterByOutline(scan);
    if (!outline.ok()) return outline.status();
    return std::vector<ModelRegistration>{*outline};
  }
  // ICP on a subsample (every k-th point, at most ~2 000) per candidate, then all points.
  std::vector<Eigen::Vector3d> subsample;
  const int stride = std::max(1, n / 2000);
  for (int i = 0; i < n; i += stride) subsample.push_back(scan[i]);
  // Each start's coarse ICP, scored: higher inlier fraction first, then lower rms.
  auto icp_from = [&](const std::vector<Similarity>& starts) {
    std::vector<std::pair<double, IcpOutcome>> scored;
    for (const Similarity& start : starts) {
      IcpOutcome icp =
          RunIcp(*tree_, surface_, subsample, start, false,
                 std::max(1, options_.icp_iterations / 2), options_.icp_max_distance_m);
      const double score = icp.inliers / static_cast<double>(subsample.size()) -
                           icp.rms_m / options_.icp_max_distance_m * 0.01;
      scored.emplace_back(score, icp);
    }
    std::stable_sort(scored.begin(), scored.end(),
                     [](const auto& a, const auto& b) { return a.first > b.first; });
    return scored;
  };
  std::vector<Candidate> chosen = CoarseCandidates(surface_, options_, scan, 0);
  std::vector<Similarity> starts;
  for (const Candidate& c : chosen) starts.push_back(c.model_from_table);
  std::vector<std::pair<double, IcpOutcome>> scored = icp_from(starts);
  const double needed = options_.min_inlier_fraction * static_cast<double>(subsample.size());
  if (scored.empty() || scored.front().second.inliers < needed) {
    // The scan's table plane may not be the model's table (a terrain whose largest slope the
    // plane fit took for the table: heights over it are not the model's): the maps of what
    // stands above its surroundings, which no plane changes, and each candidate also levelled.
    std::vector<Candidate> relief = CoarseCandidates(surface_, options_, scan, kReliefWindowCells);
    const TopMap top = ModelTop(surface_.points_m, options_.coarse_cell_m);
    starts.clear();
    for (const Candidate& c : relief) {
      starts.push_back(c.model_from_table);
      if (std::optional<Similarity> levelled = Levelled(c.model_from_table, subsample, top)) {
        starts.push_back(*levelled);
      }
    }
    std::vector<std::pair<double, IcpOutcome>> again = icp_from(starts);
    // Free to tilt, this search can fit a wrong place half well (random:9: 62 % of the points
    // within 10 mm, 4.6 mm rms, its scale 5 % off, 133 mm wrong): it must fit most of the scan.
    const double relief_needed = kReliefMinInlierFraction * static_cast<double>(subsample.size());
    if (!again.empty() && again.front().second.inliers >= relief_needed &&
        (scored.empty() || again.front().first > scored.front().first)) {
      scored = std::move(again);
      chosen = std::move(relief);
    }
  }
  if (scored.empty() || scored.front().second.inliers <
                            options_.min_inlier_fraction * static_cast<double>(subsample.size())) {
    return NotFoundError(
        "model registration: the model does not match the scanned surface (best candidate: " +
        std::to_string(scored.empty() ? 0 : scored.front().second.inliers) + " of " +
        std::to_string(subsample.size()) + " points within " +
        std::to_string(options_.icp_max_distance_m * 1e3) + " mm)");
  }
  const std::vector<Eigen::Vector3d> points = Subsample(scan, kMaxIcpPoints);
  std::vector<ModelRegistration> out;
  for (const auto& [score, icp] : scored) {
    if (static_cast<int>(out.size()) >= max_candidates) break;
    if (!out.empty() && icp.inliers < kCandidateInlierRatio * scored.front().second.inliers) break;
    // The best one refined on the full subsample (scale free as the options say); the others as
    // the coarse ICP left them, for the caller to Refine() only if it gets to them.
    ModelRegistration r;
    if (out.empty()) {
      const IcpOutcome fine = RunScaleFreeIcp(*tree_, surface_, points, icp.model_from_table,
                                              options_.estimate_scale, options_.scale_from_plan,
                                              options_.icp_iterations, options_.icp_max_distance_m);
      r = FromIcp(fine, static_cast<int>(points.size()));
    } else {
      r = FromIcp(icp, static_cast<int>(subsample.size()));
      r.coarse_only = true;
    }
    r.coarse_score = chosen.front().score;
    r.candidates_tried = static_cast<int>(chosen.size());
    r.structure_fraction = static_cast<double>(structure) / n;
    out.push_back(r);
  }
  return out;
}

Expected<ModelRegistration> ModelMatcher::Register(std::span<const Eigen::Vector3d> scan) const {
  Expected<std::vector<ModelRegistration>> candidates = RegisterCandidates(scan, 1);
  if (!candidates.ok()) return candidates.status();
  return candidates->front();
}

Expected<ModelRegistration> RegisterModel(const Scene& model,
                                          std::span<const Eigen::Vector3d> scan_in_table_m,
                                          const ModelRegistrationOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  ModelMatcher matcher(model, options);
  return matcher.Register(scan_in_table_m);
}

}  // namespace sandtable::node
