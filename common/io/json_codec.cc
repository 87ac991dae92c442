#include "common/io/json_codec.h"

#include <array>
#include <cmath>
#include <sstream>

#include <Eigen/LU>

namespace sandtable::io {

using nlohmann::json;

namespace {

constexpr int kMaxImageSide_px = 65536;

std::string Number(double x) {
  std::ostringstream s;
  s << x;
  return s.str();
}

// Unit quaternion from a stored one, or INVALID_ARGUMENT naming the field.
Expected<Eigen::Quaterniond> UnitQuaternion(const Eigen::Quaterniond& q, const std::string& field,
                                            const char* order) {
  const double norm = q.norm();
  if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance)) {
    return InvalidArgumentError(field + " has norm " + Number(norm) + ", not 1 within " +
                                Number(kQuaternionNormTolerance) + ": write a unit quaternion " +
                                order);
  }
  return q.normalized();
}

Expected<Rigid3d> ReadRigidObject(ObjectReader* r) {
  const int forms = static_cast<int>(r->Has("rotation_xyzw")) +
                    static_cast<int>(r->Has("rotation_wxyz")) +
                    static_cast<int>(r->Has("rotation"));
  if (forms == 0) {
    return ParseError(r->Field("rotation_xyzw") + " is missing (a unit quaternion [x, y, z, w])");
  }
  if (forms > 1) {
    return ParseError(r->where() +
                      " has more than one of rotation_xyzw, rotation_wxyz, rotation; give one");
  }
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  if (r->Has("rotation_xyzw")) {
    std::array<double, 4> c{};
    ST_RETURN_IF_ERROR(r->Numbers("rotation_xyzw", c));
    Expected<Eigen::Quaterniond> q = UnitQuaternion(Eigen::Quaterniond(c[3], c[0], c[1], c[2]),
                                                    r->Field("rotation_xyzw"), "[x, y, z, w]");
    if (!q.ok()) return q.status();
    rotation = *q;
  } else if (r->Has("rotation_wxyz")) {
    std::array<double, 4> c{};
    ST_RETURN_IF_ERROR(r->Numbers("rotation_wxyz", c));
    Expected<Eigen::Quaterniond> q = UnitQuaternion(Eigen::Quaterniond(c[0], c[1], c[2], c[3]),
                                                    r->Field("rotation_wxyz"), "[w, x, y, z]");
    if (!q.ok()) return q.status();
    rotation = *q;
  } else {
    std::array<double, 9> c{};
    ST_RETURN_IF_ERROR(r->Matrix("rotation", 3, 3, c));
    const Eigen::Matrix3d m =
        Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(c.data());
    const double orthonormal_error = (m.transpose() * m - Eigen::Matrix3d::Identity()).norm();
    const double det = m.determinant();
    if (!(orthonormal_error <= kRotationMatrixTolerance) || !(det > 0.0)) {
      return InvalidArgumentError(r->Field("rotation") + " is not a rotation (|R^T R - I| = " +
                                  Number(orthonormal_error) + ", det = " + Number(det) + ")");
    }
    rotation = Eigen::Quaterniond(m).normalized();
  }
  std::array<double, 3> t{};
  ST_RETURN_IF_ERROR(r->Numbers("translation_m", t));
  std::string convention;
  ST_RETURN_IF_ERROR(r->String("convention", &convention, Presence::kOptional));
  ST_RETURN_IF_ERROR(r->End());
  return Rigid3d(rotation, Eigen::Vector3d(t[0], t[1], t[2]));
}

// Version-1 unit calibration form: image_width_px, image_height_px, camera_matrix,
// distortion_coefficients (+ distortion_model, a comment).
Status ReadLegacyCameraMatrixForm(ObjectReader* r, CameraModel* model) {
  int width = 0, height = 0;
  ST_RETURN_IF_ERROR(r->Int("image_width_px", 1, kMaxImageSide_px, &width));
  ST_RETURN_IF_ERROR(r->Int("image_height_px", 1, kMaxImageSide_px, &height));
  std::array<double, 9> k{};
  ST_RETURN_IF_ERROR(r->Matrix("camera_matrix", 3, 3, k));
  if (k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0) {
    return InvalidArgumentError(r->Field("camera_matrix") +
                                " must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)");
  }
  std::array<double, 5> d{};
  ST_RETURN_IF_ERROR(r->Numbers("distortion_coefficients", d));
  std::string distortion_model;
  ST_RETURN_IF_ERROR(r->String("distortion_model", &distortion_model, Presence::kOptional));
  *model = CameraModel(width, height, k[0], k[4], k[2], k[5], BrownDistortion::FromArray(d.data()));
  return OkStatus();
}

}  // namespace

json RigidToJson(const Rigid3d& target_from_source) {
  const Eigen::Quaterniond q = target_from_source.rotation.normalized();
  const Eigen::Vector3d& t = target_from_source.translation;
  return {{"rotation_xyzw", {q.x(), q.y(), q.z(), q.w()}},
          {"translation_m", {t.x(), t.y(), t.z()}}};
}

Expected<Rigid3d> ReadRigid(ObjectReader* parent, std::string_view key) {
  Expected<ObjectReader> r = parent->Object(key);
  if (!r.ok()) return r.status();
  return ReadRigidObject(&*r);
}

Expected<Rigid3d> RigidFromJson(const json& j, std::string_view where) {
  ObjectReader r(j, std::string(where));
  ST_RETURN_IF_ERROR(r.Begin());
  return ReadRigidObject(&r);
}

json CameraModelToJson(const CameraModel& m) {
  const std::array<double, 5> d = m.distortion.ToArray();
  return {{"width_px", m.width_px},
          {"height_px", m.height_px},
          {"fx_px", m.fx_px},
          {"fy_px", m.fy_px},
          {"cx_px", m.cx_px},
          {"cy_px", m.cy_px},
          {"distortion_k1_k2_p1_p2_k3", {d[0], d[1], d[2], d[3], d[4]}}};
}

Status ReadCameraModelFields(ObjectReader* r, CameraModel* model) {
  CameraModel m;
  if (r->Has("camera_matrix") || r->Has("image_width_px")) {
    ST_RETURN_IF_ERROR(ReadLegacyCameraMatrixForm(r, &m));
  } else {
    int width = 0, height = 0;
    ST_RETURN_IF_ERROR(r->Int("width_px", 1, kMaxImageSide_px, &width));
    ST_RETURN_IF_ERROR(r->Int("height_px", 1, kMaxImageSide_px, &height));
    if (r->Has("throw_ratio")) {
      for (const char* key : {"fx_px", "fy_px", "cx_px", "cy_px"}) {
        if (r->Has(key)) {
          return ParseError(r->where() + " has both throw_ratio and " + key + "; give one form");
        }
      }
      double throw_ratio = 0.0, lens_shift_v = 0.0;
      ST_RETURN_IF_ERROR(r->Number("throw_ratio", &throw_ratio));
      ST_RETURN_IF_ERROR(r->Number("lens_shift_v", &lens_shift_v, Presence::kOptional));
      if (!(throw_ratio > 0.0)) {
        return InvalidArgumentError(r->Field("throw_ratio") + " = " + Number(throw_ratio) +
                                    " must be > 0");
      }
      m = CameraModel::FromThrowRatio(width, height, throw_ratio, lens_shift_v);
    } else {
      m.width_px = width;
      m.height_px = height;
      ST_RETURN_IF_ERROR(r->Number("fx_px", &m.fx_px));
      ST_RETURN_IF_ERROR(r->Number("fy_px", &m.fy_px));
      ST_RETURN_IF_ERROR(r->Number("cx_px", &m.cx_px));
      ST_RETURN_IF_ERROR(r->Number("cy_px", &m.cy_px));
    }
    std::array<double, 5> d{};
    ST_RETURN_IF_ERROR(r->Numbers("distortion_k1_k2_p1_p2_k3", d, Presence::kOptional));
    m.distortion = BrownDistortion::FromArray(d.data());
  }
  if (Status valid = m.Check(); !valid.ok()) {
    return InvalidArgumentError(JoinField(r->where(), valid.message()));
  }
  *model = m;
  return OkStatus();
}

Expected<CameraModel> CameraModelFromJson(const json& j, std::string_view where) {
  ObjectReader r(j, std::string(where));
  ST_RETURN_IF_ERROR(r.Begin());
  CameraModel model;
  ST_RETURN_IF_ERROR(ReadCameraModelFields(&r, &model));
  ST_RETURN_IF_ERROR(r.End());
  return model;
}

}  // namespace sandtable::io
