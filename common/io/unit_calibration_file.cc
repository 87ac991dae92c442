#include "common/io/unit_calibration_file.h"

#include <cmath>

#include "common/io/json_codec.h"
#include "common/io/json_reader.h"

namespace sandtable {

using nlohmann::json;

namespace {

// Version 1 (node/calibration before the common codec).
constexpr char kLegacyFormatV1[] = "sandtable-unit-calibration";

bool FiniteNonNegative(double x) { return std::isfinite(x) && x >= 0.0; }

Status ReadDevice(io::ObjectReader* root, const char* key, CameraModel* model) {
  Expected<io::ObjectReader> device = root->Object(key);
  if (!device.ok()) return device.status();
  ST_RETURN_IF_ERROR(io::ReadCameraModelFields(&*device, model));
  return device->End();
}

Status ReadOptionalRigid(io::ObjectReader* root, const char* key, std::optional<Rigid3d>* out) {
  if (!root->Has(key)) return OkStatus();
  Expected<Rigid3d> rigid = io::ReadRigid(root, key);
  if (!rigid.ok()) return rigid.status();
  *out = *rigid;
  return OkStatus();
}

Status ReadRms(io::ObjectReader* root, const char* key, double* out) {
  ST_RETURN_IF_ERROR(root->Number(key, out, io::Presence::kOptional));
  if (*out < 0.0) {
    return InvalidArgumentError(root->Field(key) + " = " + std::to_string(*out) + " must be >= 0");
  }
  return OkStatus();
}

}  // namespace

Status UnitCalibration::Check() const {
  ST_RETURN_IF_ERROR(camera.Check().WithContext("camera"));
  ST_RETURN_IF_ERROR(projector.Check().WithContext("projector"));
  if (!projector_from_camera.AllFinite()) {
    return InvalidArgumentError("projector_from_camera is not finite");
  }
  if (table_from_projector && !table_from_projector->AllFinite()) {
    return InvalidArgumentError("table_from_projector is not finite");
  }
  if (table_from_model && !table_from_model->AllFinite()) {
    return InvalidArgumentError("table_from_model is not finite");
  }
  if (!FiniteNonNegative(camera_rms_px) || !FiniteNonNegative(projector_rms_px)) {
    return InvalidArgumentError("camera_rms_px and projector_rms_px must be finite and >= 0");
  }
  if (projector_response &&
      (!(projector_response->gamma >= 0.5 && projector_response->gamma <= 5.0) ||
       !(projector_response->black_level < 1.0))) {
    return InvalidArgumentError(
        "projector_response: gamma = " + std::to_string(projector_response->gamma) +
        " must be in [0.5, 5] and black_level < 1");
  }
  if (predicted_error &&
      (!FiniteNonNegative(predicted_error->rms_px) || !std::isfinite(predicted_error->rms_mm) ||
       predicted_error->samples < 0 || !FiniteNonNegative(predicted_error->sigma_px) ||
       !(predicted_error->weak_share >= 0.0 && predicted_error->weak_share <= 1.0))) {
    return InvalidArgumentError(
        "predicted_error: rms_px, sigma_px and samples must be finite and >= 0, rms_mm finite, "
        "weak_share in [0, 1]");
  }
  if (unit_id != kInvalidNodeId && !IsValidNodeId(unit_id)) {
    return InvalidArgumentError("unit_id = " + std::to_string(unit_id) +
                                " is a reserved sender id, not a node id");
  }
  return OkStatus();
}

json UnitCalibrationToJsonValue(const UnitCalibration& c) {
  json root{{"format", kUnitCalibrationFormat},
            {"version", kUnitCalibrationVersion},
            {"camera", io::CameraModelToJson(c.camera)},
            {"projector", io::CameraModelToJson(c.projector)},
            {"projector_from_camera", io::RigidToJson(c.projector_from_camera)}};
  if (c.unit_id != kInvalidNodeId) root["unit_id"] = c.unit_id;
  if (!c.source.empty()) root["source"] = c.source;
  if (c.table_from_projector)
    root["table_from_projector"] = io::RigidToJson(*c.table_from_projector);
  if (c.table_from_model) root["table_from_model"] = io::RigidToJson(*c.table_from_model);
  if (!c.poses_used.empty() || c.camera_rms_px != 0.0 || c.projector_rms_px != 0.0) {
    root["camera_rms_px"] = c.camera_rms_px;
    root["projector_rms_px"] = c.projector_rms_px;
    root["poses_used"] = c.poses_used;
  }
  if (c.projector_response) {
    root["projector_response"] = {{"gamma", c.projector_response->gamma}};
    if (c.projector_response->black_level >= 0.0) {
      root["projector_response"]["black_level"] = c.projector_response->black_level;
    }
  }
  if (c.predicted_error) {
    const PredictedErrorRecord& p = *c.predicted_error;
    json predicted{{"rms_px", p.rms_px},         {"samples", p.samples},
                   {"sigma_px", p.sigma_px},     {"weak_direction", p.weak_direction},
                   {"weak_share", p.weak_share}, {"undetermined", p.undetermined}};
    if (p.rms_mm >= 0.0) predicted["rms_mm"] = p.rms_mm;
    root["predicted_error"] = predicted;
  }
  return root;
}

std::string UnitCalibrationToJson(const UnitCalibration& c) {
  return UnitCalibrationToJsonValue(c).dump(2, ' ', false, json::error_handler_t::replace) + "\n";
}

Expected<UnitCalibration> UnitCalibrationFromJson(const json& j, std::string_view source) {
  io::ObjectReader root(j, std::string(source) + ":");
  ST_RETURN_IF_ERROR(root.Begin());
  UnitCalibration c;
  if (!root.Has("format")) {
    // A factory file of make-site --factory-dir from before files carried format/version.
    if (!root.Has("unit_id") || !root.Has("projector_from_camera")) {
      return ParseError(root.Field("format") + " is missing (\"" + kUnitCalibrationFormat +
                        "\", version " + std::to_string(kUnitCalibrationVersion) + ")");
    }
    c.source = kSourceFactory;
  } else if (j["format"] == kLegacyFormatV1) {
    Expected<int> version = io::ReadFormatVersion(&root, kLegacyFormatV1, 1, 1);
    if (!version.ok()) return version.status();
    c.source = kSourceUnitCalibration;
  } else {
    Expected<int> version = io::ReadFormatVersion(&root, kUnitCalibrationFormat, 2, 2);
    if (!version.ok()) return version.status();
  }
  int64_t unit_id = 0;
  if (root.Has("unit_id")) {
    ST_RETURN_IF_ERROR(root.Integer("unit_id", 0, kFirstReservedSenderId - 1, &unit_id));
    c.unit_id = static_cast<NodeId>(unit_id);
  }
  ST_RETURN_IF_ERROR(root.String("source", &c.source, io::Presence::kOptional));
  ST_RETURN_IF_ERROR(ReadDevice(&root, "camera", &c.camera));
  ST_RETURN_IF_ERROR(ReadDevice(&root, "projector", &c.projector));
  Expected<Rigid3d> projector_from_camera = io::ReadRigid(&root, "projector_from_camera");
  if (!projector_from_camera.ok()) return projector_from_camera.status();
  c.projector_from_camera = *projector_from_camera;
  ST_RETURN_IF_ERROR(ReadOptionalRigid(&root, "table_from_projector", &c.table_from_projector));
  ST_RETURN_IF_ERROR(ReadOptionalRigid(&root, "table_from_model", &c.table_from_model));
  ST_RETURN_IF_ERROR(ReadRms(&root, "camera_rms_px", &c.camera_rms_px));
  ST_RETURN_IF_ERROR(ReadRms(&root, "projector_rms_px", &c.projector_rms_px));
  ST_RETURN_IF_ERROR(root.Strings("poses_used", &c.poses_used, io::Presence::kOptional));
  if (root.Has("projector_response")) {
    Expected<io::ObjectReader> response = root.Object("projector_response");
    if (!response.ok()) return response.status();
    ProjectorResponseRecord r;
    ST_RETURN_IF_ERROR(response->Number("gamma", &r.gamma, io::Presence::kRequired));
    ST_RETURN_IF_ERROR(response->Number("black_level", &r.black_level, io::Presence::kOptional));
    ST_RETURN_IF_ERROR(response->End());
    c.projector_response = r;
  }
  if (root.Has("predicted_error")) {
    Expected<io::ObjectReader> in = root.Object("predicted_error");
    if (!in.ok()) return in.status();
    PredictedErrorRecord p;
    int64_t samples = 0;
    ST_RETURN_IF_ERROR(in->Number("rms_px", &p.rms_px, io::Presence::kRequired));
    ST_RETURN_IF_ERROR(in->Number("rms_mm", &p.rms_mm, io::Presence::kOptional));
    ST_RETURN_IF_ERROR(in->Integer("samples", 0, 1 << 30, &samples));
    p.samples = static_cast<int>(samples);
    ST_RETURN_IF_ERROR(in->Number("sigma_px", &p.sigma_px, io::Presence::kOptional));
    ST_RETURN_IF_ERROR(in->String("weak_direction", &p.weak_direction, io::Presence::kOptional));
    ST_RETURN_IF_ERROR(in->Number("weak_share", &p.weak_share, io::Presence::kOptional));
    ST_RETURN_IF_ERROR(in->String("undetermined", &p.undetermined, io::Presence::kOptional));
    ST_RETURN_IF_ERROR(in->End());
    c.predicted_error = p;
  }
  ST_RETURN_IF_ERROR(root.End());
  if (Status valid = c.Check(); !valid.ok()) return valid.WithContext(source);
  return c;
}

Expected<UnitCalibration> ParseUnitCalibration(std::string_view text, std::string_view source) {
  Expected<json> j = io::ParseJsonText(text, source);
  if (!j.ok()) return j.status();
  return UnitCalibrationFromJson(*j, source);
}

Status SaveUnitCalibration(const UnitCalibration& calibration, const std::string& path) {
  if (Status valid = calibration.Check(); !valid.ok()) return valid.WithContext(path);
  return io::WriteTextFile(UnitCalibrationToJson(calibration), path);
}

Expected<UnitCalibration> LoadUnitCalibration(const std::string& path) {
  Expected<json> j = io::ReadJsonFile(path);
  if (!j.ok()) return j.status();
  return UnitCalibrationFromJson(*j, path);
}

}  // namespace sandtable
