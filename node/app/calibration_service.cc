#include "node/app/calibration_service.h"

#include <filesystem>

#include <nlohmann/json.hpp>

#include "common/base/file_io.h"
#include "common/io/json_codec.h"
#include "common/io/json_reader.h"
#include "common/io/opencv_yaml.h"

namespace sandtable::node {
namespace {

constexpr const char* kTruePoseFormat = "sandtable.true_pose";
constexpr int kTruePoseVersion = 1;

}  // namespace

Expected<TruePose> ParseTruePose(const std::string& json_text, const std::string& source) {
  nlohmann::json root = nlohmann::json::parse(json_text, nullptr, /*allow_exceptions=*/false);
  if (root.is_discarded()) return ParseError(source + ": not valid JSON");
  io::ObjectReader reader(root, source + ":");
  ST_RETURN_IF_ERROR(reader.Begin());
  std::string format;
  ST_RETURN_IF_ERROR(reader.String("format", &format));
  if (format != kTruePoseFormat) {
    return ParseError(reader.Field("format") + " must be \"" + kTruePoseFormat + "\"");
  }
  int version = 0;
  ST_RETURN_IF_ERROR(reader.Int("version", kTruePoseVersion, kTruePoseVersion, &version));
  TruePose pose;
  int64_t id = 0;
  ST_RETURN_IF_ERROR(reader.Integer("unit_id", 0, kFirstReservedSenderId - 1, &id));
  pose.unit_id = static_cast<NodeId>(id);
  for (auto [key, out] : {std::pair{"table_from_projector", &pose.table_from_projector},
                          std::pair{"table_from_model", &pose.table_from_model}}) {
    const nlohmann::json* j = reader.Find(key);
    if (!j) return ParseError(reader.Field(key) + " is missing");
    Expected<Rigid3d> rigid = io::RigidFromJson(*j, reader.Field(key));
    if (!rigid.ok()) return rigid.status();
    *out = *rigid;
  }
  ST_RETURN_IF_ERROR(reader.End());
  return pose;
}

Expected<TruePose> LoadTruePose(const std::string& path) {
  Expected<std::string> text = ReadInputFile(path, io::kMaxJsonFileBytes, "kMaxJsonFileBytes");
  if (!text.ok()) return IoError(text.status().message());  // the message names the path
  return ParseTruePose(*text, path);
}

std::string TruePoseToJson(const TruePose& pose) {
  nlohmann::json root{{"format", kTruePoseFormat},
                      {"version", kTruePoseVersion},
                      {"unit_id", pose.unit_id},
                      {"table_from_projector", io::RigidToJson(pose.table_from_projector)},
                      {"table_from_model", io::RigidToJson(pose.table_from_model)}};
  return root.dump(2) + "\n";
}

Expected<UnitCalibration> ComposeTruePoseCalibration(const UnitCalibration& factory,
                                                     const TruePose& pose) {
  if (factory.unit_id != kInvalidNodeId && factory.unit_id != pose.unit_id) {
    return InvalidArgumentError("true pose is for unit " + std::to_string(pose.unit_id) +
                                ", the factory file for unit " + std::to_string(factory.unit_id));
  }
  UnitCalibration out = factory;
  out.unit_id = pose.unit_id;
  out.source = "factory+true_pose";
  out.table_from_projector = pose.table_from_projector;
  out.table_from_model = pose.table_from_model;
  ST_RETURN_IF_ERROR(out.Check());
  return out;
}

Expected<ExportedCalibration> ExportCalibration(const UnitCalibration& calibration,
                                                const std::string& directory) {
  std::error_code error;
  std::filesystem::create_directories(directory, error);
  if (error) return IoError("cannot create " + directory + ": " + error.message());
  const std::string stem =
      (std::filesystem::path(directory) / ("unit-" + std::to_string(calibration.unit_id))).string();
  ExportedCalibration out;
  out.json_path = stem + ".json";
  ST_RETURN_IF_ERROR(WriteFileAtomically(out.json_path, UnitCalibrationToJson(calibration)));
  if (calibration.table_from_projector && calibration.table_from_model) {
    out.yaml_path = stem + ".yaml";
    ST_RETURN_IF_ERROR(WriteOpenCvYaml(calibration, out.yaml_path));  // atomic
  }
  return out;
}

}  // namespace sandtable::node
