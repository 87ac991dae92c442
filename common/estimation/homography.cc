#include "common/estimation/homography.h"

#include <array>
#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/LU>
#include <Eigen/SVD>

#include "common/estimation/homography_hartley.h"
#include "common/estimation/ransac.h"

namespace sandtable {
namespace {

Status CheckPairs(std::string_view what, std::span<const Eigen::Vector2d> from,
                  std::span<const Eigen::Vector2d> to) {
  if (from.size() != to.size()) {
    std::ostringstream s;
    s << what << ": " << from.size() << " source points but " << to.size() << " destination points";
    return InvalidArgumentError(s.str());
  }
  for (size_t i = 0; i < from.size(); ++i) {
    if (!from[i].allFinite() || !to[i].allFinite()) {
      std::ostringstream s;
      s << what << ": pair " << i << " has a non-finite coordinate (NaN or Inf)";
      return InvalidArgumentError(s.str());
    }
  }
  if (from.size() < 4) {
    std::ostringstream s;
    s << what << ": " << from.size() << " point pairs given, at least 4 needed";
    return DegenerateError(s.str());
  }
  return OkStatus();
}

// Three of the four points collinear (the minimal case): the 8x9 system then has a null space
// of dimension > 1 and the "homography" it returns is meaningless.
bool HasCollinearTriple(const std::array<Eigen::Vector2d, 4>& p) {
  constexpr int kTriples[4][3] = {{0, 1, 2}, {0, 1, 3}, {0, 2, 3}, {1, 2, 3}};
  for (const auto& t : kTriples) {
    const std::array<Eigen::Vector2d, 3> tri = {p[t[0]], p[t[1]], p[t[2]]};
    if (internal::CollinearityRatio(tri) < kHomographyCollinearRatio) return true;
  }
  return false;
}

// DLT on inputs already validated (sizes, finite, n >= 4).
Expected<Eigen::Matrix3d> DltUnchecked(std::span<const Eigen::Vector2d> from,
                                       std::span<const Eigen::Vector2d> to) {
  const int n = static_cast<int>(from.size());
  for (const auto& [points, name] : {std::pair{from, "source"}, std::pair{to, "destination"}}) {
    const double ratio = internal::CollinearityRatio(points);
    if (ratio < kHomographyCollinearRatio) {
      std::ostringstream s;
      s << "homography: the " << name << " points are collinear (spread ratio " << ratio << " < "
        << kHomographyCollinearRatio << "); a homography needs 4 points in general "
        << "position";
      return DegenerateError(s.str());
    }
    if (n == 4) {
      std::array<Eigen::Vector2d, 4> p = {points[0], points[1], points[2], points[3]};
      if (HasCollinearTriple(p)) {
        std::ostringstream s;
        s << "homography: three of the four " << name << " points are collinear";
        return DegenerateError(s.str());
      }
    }
  }
  const internal::Hartley2d nf = internal::ComputeHartley2d(from);
  const internal::Hartley2d nt = internal::ComputeHartley2d(to);
  ST_CHECK(nf.ok && nt.ok) << "collinearity test must reject coincident points";

  // Each pair gives two rows of A h = 0 with h the row-major H (Hartley & Zisserman eq. 4.3):
  //   [ 0 0 0  -x -y -1   v x  v y  v ]
  //   [ x y 1   0  0  0  -u x -u y -u ]
  Eigen::Matrix<double, Eigen::Dynamic, 9> a(2 * n, 9);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d x = nf.Apply(from[i]);
    const Eigen::Vector2d u = nt.Apply(to[i]);
    a.row(2 * i) << 0, 0, 0, -x.x(), -x.y(), -1, u.y() * x.x(), u.y() * x.y(), u.y();
    a.row(2 * i + 1) << x.x(), x.y(), 1, 0, 0, 0, -u.x() * x.x(), -u.x() * x.y(), -u.x();
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeFullV);
  // Pad to 9 singular values (n = 4 gives an 8x9 system with 8).
  Eigen::Matrix<double, 9, 1> sv = Eigen::Matrix<double, 9, 1>::Zero();
  sv.head(svd.singularValues().size()) = svd.singularValues();
  if (!(sv(7) > kHomographyRankDeficientRatio * sv(0))) {
    std::ostringstream s;
    s << "homography: the linear system is rank-deficient (singular values s8/s1 = "
      << sv(7) / sv(0) << "); the points do not determine a unique homography";
    return DegenerateError(s.str());
  }
  const Eigen::Matrix<double, 9, 1> h = svd.matrixV().col(8);
  Eigen::Matrix3d hn;
  hn << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), h(8);
  const Eigen::JacobiSVD<Eigen::Matrix3d> hsvd(hn);
  if (!(hsvd.singularValues()(2) > kHomographySingularRatio * hsvd.singularValues()(0))) {
    return DegenerateError(
        "homography: the estimate is singular (it maps the plane onto a line); the point "
        "pairs are inconsistent with an invertible homography");
  }
  return NormalizeHomography(nt.t.inverse() * hn * nf.t);
}

// RANSAC estimator over minimal 4-point DLT samples (see ransac.h for the interface).
class HomographyRansacEstimator {
 public:
  using Model = Eigen::Matrix3d;
  static constexpr int kMinSamples = 4;

  HomographyRansacEstimator(std::span<const Eigen::Vector2d> from,
                            std::span<const Eigen::Vector2d> to)
      : from_(from), to_(to) {}

  int NumData() const { return static_cast<int>(from_.size()); }

  std::vector<Model> FitMinimal(std::span<const int> sample) const {
    std::array<Eigen::Vector2d, 4> f, t;
    for (int j = 0; j < 4; ++j) {
      f[j] = from_[sample[j]];
      t[j] = to_[sample[j]];
    }
    // Degenerate minimal samples are rejected before the SVD (cheap, and their "model" would
    // be arbitrary).
    if (HasCollinearTriple(f) || HasCollinearTriple(t)) return {};
    Expected<Model> h = DltUnchecked(f, t);
    if (!h.ok()) return {};
    return {*h};
  }

  double Residual(const Model& h, int i) const {
    return (to_[i] - ApplyHomography(h, from_[i])).norm();
  }

  std::optional<Model> FitInliers(std::span<const int> inliers) const {
    if (inliers.size() < 4) return std::nullopt;
    std::vector<Eigen::Vector2d> f, t;
    f.reserve(inliers.size());
    t.reserve(inliers.size());
    for (int i : inliers) {
      f.push_back(from_[i]);
      t.push_back(to_[i]);
    }
    Expected<Model> h = DltUnchecked(f, t);
    if (!h.ok()) return std::nullopt;
    return *h;
  }

 private:
  std::span<const Eigen::Vector2d> from_;
  std::span<const Eigen::Vector2d> to_;
};

}  // namespace

Eigen::Vector2d ApplyHomography(const Eigen::Matrix3d& to_from_from, const Eigen::Vector2d& x) {
  const Eigen::Vector3d y = to_from_from * x.homogeneous();
  return y.head<2>() / y.z();
}

Eigen::Matrix3d NormalizeHomography(const Eigen::Matrix3d& h) {
  const double norm = h.norm();
  if (!(norm > 0.0)) return h;
  Eigen::Matrix3d out = h / norm;
  for (int c = 2; c >= 0; --c) {
    if (out(2, c) != 0.0) {
      if (out(2, c) < 0.0) out = -out;
      break;
    }
  }
  return out;
}

std::vector<double> HomographyTransferErrors(const Eigen::Matrix3d& to_from_from,
                                             std::span<const Eigen::Vector2d> points_from,
                                             std::span<const Eigen::Vector2d> points_to) {
  ST_CHECK(points_from.size() == points_to.size()) << "HomographyTransferErrors: size mismatch";
  std::vector<double> errors(points_from.size());
  for (size_t i = 0; i < points_from.size(); ++i) {
    errors[i] = (points_to[i] - ApplyHomography(to_from_from, points_from[i])).norm();
  }
  return errors;
}

double HomographyTransferRms(const Eigen::Matrix3d& to_from_from,
                             std::span<const Eigen::Vector2d> points_from,
                             std::span<const Eigen::Vector2d> points_to) {
  if (points_from.empty()) return 0.0;
  double sum_sq = 0.0;
  for (double e : HomographyTransferErrors(to_from_from, points_from, points_to)) {
    if (!std::isfinite(e)) return std::numeric_limits<double>::infinity();
    sum_sq += e * e;
  }
  return std::sqrt(sum_sq / static_cast<double>(points_from.size()));
}

Expected<Eigen::Matrix3d> EstimateHomographyDlt(std::span<const Eigen::Vector2d> points_from,
                                                std::span<const Eigen::Vector2d> points_to) {
  ST_RETURN_IF_ERROR(CheckPairs("homography DLT", points_from, points_to));
  return DltUnchecked(points_from, points_to);
}

Status HomographyRansacOptions::Check() const {
  if (!(max_transfer_error_px > 0.0) || !std::isfinite(max_transfer_error_px)) {
    return InvalidArgumentError(
        "HomographyRansacOptions: max_transfer_error_px must be finite and > 0");
  }
  ST_RETURN_IF_ERROR(refine_options.Check());
  return OkStatus();  // the remaining fields are checked by RansacOptions::Check
}

Expected<HomographyRansacResult> EstimateHomographyRansac(
    std::span<const Eigen::Vector2d> points_from, std::span<const Eigen::Vector2d> points_to,
    const HomographyRansacOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  ST_RETURN_IF_ERROR(CheckPairs("homography RANSAC", points_from, points_to));
  RansacOptions ransac;
  ransac.max_error = options.max_transfer_error_px;
  ransac.confidence = options.confidence;
  ransac.min_iterations = options.min_iterations;
  ransac.max_iterations = options.max_iterations;
  ransac.min_inlier_ratio = options.min_inlier_ratio;
  ransac.seed = options.seed;
  const HomographyRansacEstimator estimator(points_from, points_to);
  auto found = Ransac(estimator, ransac);
  if (!found.ok()) return found.status().WithContext("homography");

  HomographyRansacResult result;
  result.to_from_from = found->model;
  result.inlier_mask = found->inlier_mask;
  result.num_inliers = found->num_inliers;
  result.iterations = found->iterations;

  auto inlier_sets = [&](const std::vector<char>& mask) {
    std::pair<std::vector<Eigen::Vector2d>, std::vector<Eigen::Vector2d>> sets;
    for (size_t i = 0; i < mask.size(); ++i) {
      if (mask[i]) {
        sets.first.push_back(points_from[i]);
        sets.second.push_back(points_to[i]);
      }
    }
    return sets;
  };
  if (options.refine && result.num_inliers >= 4) {
    const auto [f, t] = inlier_sets(result.inlier_mask);
    Expected<RefinedHomography> refined =
        RefineHomography(f, t, result.to_from_from, options.refine_options);
    if (refined.ok()) {
      // Re-score: keep the refined model only if it does not lose inliers.
      std::vector<char> mask(points_from.size());
      int count = 0;
      for (size_t i = 0; i < points_from.size(); ++i) {
        const double e =
            (points_to[i] - ApplyHomography(refined->to_from_from, points_from[i])).norm();
        mask[i] = std::isfinite(e) && e <= options.max_transfer_error_px;
        count += mask[i];
      }
      if (count >= result.num_inliers) {
        result.to_from_from = refined->to_from_from;
        result.inlier_mask = std::move(mask);
        result.num_inliers = count;
        result.refined = true;
      }
    }
  }
  result.inlier_ratio = static_cast<double>(result.num_inliers) / points_from.size();
  const auto [f, t] = inlier_sets(result.inlier_mask);
  result.inlier_rms_px = HomographyTransferRms(result.to_from_from, f, t);
  return result;
}

Expected<Rigid3d> CameraFromPlaneHomography(const Eigen::Matrix3d& image_from_plane,
                                            const Eigen::Matrix3d& k,
                                            std::span<const Eigen::Vector2d> points_on_plane) {
  if (!image_from_plane.allFinite() || !k.allFinite()) {
    return InvalidArgumentError("plane pose: homography or K has a non-finite entry");
  }
  const Eigen::FullPivLU<Eigen::Matrix3d> k_lu(k);
  if (!k_lu.isInvertible()) return InvalidArgumentError("plane pose: K is not invertible");
  // K^-1 H = lambda [r1 r2 t]; r1 and r2 are unit vectors, so 1/lambda is their length. The
  // two lengths differ under noise; their mean is used.
  const Eigen::Matrix3d b = k_lu.solve(image_from_plane);
  const double n1 = b.col(0).norm();
  const double n2 = b.col(1).norm();
  const double largest = std::max(n1, n2);
  if (!(std::min(n1, n2) > 1e-9 * largest) ||
      !(b.col(0).cross(b.col(1)).norm() > 1e-9 * largest * largest)) {
    return DegenerateError(
        "plane pose: K^-1 H has rank < 2 (the plane is seen edge-on or H is singular)");
  }
  double lambda = 2.0 / (n1 + n2);
  // Depth of plane point (x, y) is lambda * (b.row(2) . (x, y, 1)); make it positive.
  int in_front = 0, behind = 0;
  if (points_on_plane.empty()) {
    (b(2, 2) >= 0.0 ? in_front : behind) = 1;
  } else {
    for (const Eigen::Vector2d& p : points_on_plane) {
      const double depth = b.row(2).dot(p.homogeneous());
      if (depth > 0.0) ++in_front;
      if (depth < 0.0) ++behind;
    }
  }
  if (in_front > 0 && behind > 0) {
    std::ostringstream s;
    s << "plane pose: the plane points lie on both sides of the camera (" << in_front
      << " in front, " << behind << " behind); H is not a camera view of them";
    return OutOfRangeError(s.str());
  }
  if (behind > 0) lambda = -lambda;
  const Eigen::Vector3d r1 = lambda * b.col(0);
  const Eigen::Vector3d r2 = lambda * b.col(1);
  Eigen::Matrix3d r;
  r << r1, r2, r1.cross(r2);
  // Nearest rotation in the Frobenius sense: U V^T, with the last singular direction flipped
  // if that would be a reflection.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  const Eigen::Matrix3d rotation = svd.matrixU() * d * svd.matrixV().transpose();
  return Rigid3d(rotation, Eigen::Vector3d(lambda * b.col(2)));
}

}  // namespace sandtable
