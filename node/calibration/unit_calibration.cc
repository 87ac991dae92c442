#include "node/calibration/unit_calibration.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include <Eigen/SVD>
#include <nlohmann/json.hpp>

namespace sandtable::node {
namespace {

using Json = nlohmann::json;

constexpr char kFormat[] = "sandtable-unit-calibration";
constexpr int kVersion = 1;
// A stored rotation must be orthonormal to this (9 decimal digits are written).
constexpr double kRotationTolerance = 1e-6;

Json Matrix3ToJson(const Eigen::Matrix3d& m) {
  Json rows = Json::array();
  for (int r = 0; r < 3; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2)});
  return rows;
}

Json DeviceToJson(const CameraModel& model) {
  const auto d = model.distortion.ToArray();
  return Json{{"image_width_px", model.width_px},
              {"image_height_px", model.height_px},
              {"camera_matrix", Matrix3ToJson(model.K())},
              {"distortion_coefficients", {d[0], d[1], d[2], d[3], d[4]}},
              {"distortion_model", "opencv k1 k2 p1 p2 k3"}};
}

// Field readers: every error names the full field path.
class Reader {
 public:
  explicit Reader(std::string_view source) : source_(source) {}

  Status Error(const std::string& field, const std::string& what) const {
    return ParseError(std::string(source_) + ": " + field + " " + what);
  }
  Status Invalid(const std::string& field, const std::string& what) const {
    return InvalidArgumentError(std::string(source_) + ": " + field + " " + what);
  }

  Expected<const Json*> Member(const Json& object, const std::string& parent,
                               const std::string& key) const {
    const std::string field = parent.empty() ? key : parent + "." + key;
    if (!object.is_object()) return Error(parent.empty() ? "<root>" : parent, "is not an object");
    auto it = object.find(key);
    if (it == object.end()) return Error(field, "is missing");
    return &*it;
  }

  Expected<double> Number(const Json& value, const std::string& field) const {
    if (!value.is_number()) return Error(field, "must be a number");
    const double x = value.get<double>();
    if (!std::isfinite(x)) return Invalid(field, "is not finite");
    return x;
  }

  Expected<Eigen::Matrix3d> Matrix3(const Json& value, const std::string& field) const {
    if (!value.is_array() || value.size() != 3) return Error(field, "must be a 3x3 array of rows");
    Eigen::Matrix3d m;
    for (int r = 0; r < 3; ++r) {
      if (!value[r].is_array() || value[r].size() != 3) {
        return Error(field + "[" + std::to_string(r) + "]", "must be an array of 3 numbers");
      }
      for (int c = 0; c < 3; ++c) {
        auto x =
            Number(value[r][c], field + "[" + std::to_string(r) + "][" + std::to_string(c) + "]");
        if (!x.ok()) return x.status();
        m(r, c) = *x;
      }
    }
    return m;
  }

  Expected<std::vector<double>> Vector(const Json& value, const std::string& field,
                                       size_t size) const {
    if (!value.is_array() || value.size() != size) {
      return Error(field, "must be an array of " + std::to_string(size) + " numbers");
    }
    std::vector<double> out;
    for (size_t i = 0; i < size; ++i) {
      auto x = Number(value[i], field + "[" + std::to_string(i) + "]");
      if (!x.ok()) return x.status();
      out.push_back(*x);
    }
    return out;
  }

  Expected<int> Integer(const Json& value, const std::string& field) const {
    if (!value.is_number_integer()) return Error(field, "must be an integer");
    const int64_t x = value.get<int64_t>();
    if (x < 1 || x > 65536)
      return Invalid(field, "= " + std::to_string(x) + " must be in [1, 65536]");
    return static_cast<int>(x);
  }

  Expected<CameraModel> Device(const Json& root, const std::string& key) const {
    auto object = Member(root, "", key);
    if (!object.ok()) return object.status();
    CameraModel model;
    auto width = Member(**object, key, "image_width_px");
    if (!width.ok()) return width.status();
    auto w = Integer(**width, key + ".image_width_px");
    if (!w.ok()) return w.status();
    auto height = Member(**object, key, "image_height_px");
    if (!height.ok()) return height.status();
    auto h = Integer(**height, key + ".image_height_px");
    if (!h.ok()) return h.status();
    auto km = Member(**object, key, "camera_matrix");
    if (!km.ok()) return km.status();
    auto k = Matrix3(**km, key + ".camera_matrix");
    if (!k.ok()) return k.status();
    const Eigen::Matrix3d& K = *k;
    if (K(0, 1) != 0.0 || K(1, 0) != 0.0 || K(2, 0) != 0.0 || K(2, 1) != 0.0 || K(2, 2) != 1.0) {
      return Invalid(key + ".camera_matrix",
                     "must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)");
    }
    auto dm = Member(**object, key, "distortion_coefficients");
    if (!dm.ok()) return dm.status();
    auto d = Vector(**dm, key + ".distortion_coefficients", 5);
    if (!d.ok()) return d.status();
    model = CameraModel::FromK(*w, *h, K, BrownDistortion::FromArray(d->data()));
    Status valid = model.Check();
    if (!valid.ok()) return Invalid(key, valid.message());
    return model;
  }

 private:
  std::string_view source_;
};

}  // namespace

Status UnitCalibration::Check() const {
  ST_RETURN_IF_ERROR(camera.Check().WithContext("camera: "));
  ST_RETURN_IF_ERROR(projector.Check().WithContext("projector: "));
  if (!projector_from_camera.AllFinite()) {
    return InvalidArgumentError("projector_from_camera is not finite");
  }
  if (!(camera_rms_px >= 0.0) || !std::isfinite(camera_rms_px) || !(projector_rms_px >= 0.0) ||
      !std::isfinite(projector_rms_px)) {
    return InvalidArgumentError("rms errors must be finite and >= 0");
  }
  return OkStatus();
}

std::string UnitCalibrationToJson(const UnitCalibration& c) {
  const Eigen::Vector3d& t = c.projector_from_camera.translation;
  Json root{{"format", kFormat},
            {"version", kVersion},
            {"camera", DeviceToJson(c.camera)},
            {"projector", DeviceToJson(c.projector)},
            {"projector_from_camera",
             {{"rotation", Matrix3ToJson(c.projector_from_camera.RotationMatrix())},
              {"translation_m", {t.x(), t.y(), t.z()}},
              {"convention", "x_in_projector = rotation * x_in_camera + translation_m"}}},
            {"camera_rms_px", c.camera_rms_px},
            {"projector_rms_px", c.projector_rms_px},
            {"poses_used", c.poses_used}};
  return root.dump(2) + "\n";
}

Expected<UnitCalibration> ParseUnitCalibration(std::string_view text, std::string_view source) {
  Reader reader(source);
  Json root = Json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (root.is_discarded()) return ParseError(std::string(source) + ": not valid JSON");
  if (!root.is_object()) return reader.Error("<root>", "is not an object");

  auto format = reader.Member(root, "", "format");
  if (!format.ok()) return format.status();
  if (!(*format)->is_string() || (*format)->get<std::string>() != kFormat) {
    return reader.Error("format", std::string("must be \"") + kFormat + "\"");
  }
  auto version = reader.Member(root, "", "version");
  if (!version.ok()) return version.status();
  if (!(*version)->is_number_integer() || (*version)->get<int>() != kVersion) {
    return reader.Error("version", "must be " + std::to_string(kVersion));
  }

  UnitCalibration c;
  auto camera = reader.Device(root, "camera");
  if (!camera.ok()) return camera.status();
  c.camera = *camera;
  auto projector = reader.Device(root, "projector");
  if (!projector.ok()) return projector.status();
  c.projector = *projector;

  auto pose = reader.Member(root, "", "projector_from_camera");
  if (!pose.ok()) return pose.status();
  auto rj = reader.Member(**pose, "projector_from_camera", "rotation");
  if (!rj.ok()) return rj.status();
  auto r = reader.Matrix3(**rj, "projector_from_camera.rotation");
  if (!r.ok()) return r.status();
  const double orthonormal_error = (r->transpose() * *r - Eigen::Matrix3d::Identity()).norm();
  if (orthonormal_error > kRotationTolerance || r->determinant() < 0.0) {
    return reader.Invalid("projector_from_camera.rotation",
                          "is not a rotation (|R^T R - I| = " + std::to_string(orthonormal_error) +
                              ", det = " + std::to_string(r->determinant()) + ")");
  }
  auto tj = reader.Member(**pose, "projector_from_camera", "translation_m");
  if (!tj.ok()) return tj.status();
  auto t = reader.Vector(**tj, "projector_from_camera.translation_m", 3);
  if (!t.ok()) return t.status();
  c.projector_from_camera = Rigid3d(*r, Eigen::Vector3d((*t)[0], (*t)[1], (*t)[2]));

  for (const char* key : {"camera_rms_px", "projector_rms_px"}) {
    auto m = reader.Member(root, "", key);
    if (!m.ok()) return m.status();
    auto x = reader.Number(**m, key);
    if (!x.ok()) return x.status();
    if (*x < 0.0) return reader.Invalid(key, "must be >= 0");
    (std::string(key) == "camera_rms_px" ? c.camera_rms_px : c.projector_rms_px) = *x;
  }
  auto poses = reader.Member(root, "", "poses_used");
  if (!poses.ok()) return poses.status();
  if (!(*poses)->is_array()) return reader.Error("poses_used", "must be an array of strings");
  for (size_t i = 0; i < (*poses)->size(); ++i) {
    const Json& name = (**poses)[i];
    if (!name.is_string()) {
      return reader.Error("poses_used[" + std::to_string(i) + "]", "must be a string");
    }
    c.poses_used.push_back(name.get<std::string>());
  }
  return c;
}

Status SaveUnitCalibration(const UnitCalibration& calibration, const std::string& path) {
  std::ofstream out(path);
  if (!out) return IoError(path + ": cannot open for writing");
  out << UnitCalibrationToJson(calibration);
  out.close();
  if (!out) return IoError(path + ": write failed");
  return OkStatus();
}

Expected<UnitCalibration> LoadUnitCalibration(const std::string& path) {
  std::ifstream in(path);
  if (!in) return IoError(path + ": cannot open for reading");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return IoError(path + ": read failed");
  return ParseUnitCalibration(text.str(), path);
}

}  // namespace sandtable::node
