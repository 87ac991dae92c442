#include "common/io/opencv_yaml.h"

#include <exception>

#include <array>
#include <cmath>

#include <opencv2/core.hpp>

#include "common/base/file_io.h"
#include "common/io/json_reader.h"

namespace sandtable {

namespace {

// OpenCV writes "%YAML:1.0", its own spelling, which YAML parsers other than OpenCV's reject
// (the directive is "%YAML 1.0"); cv::FileStorage reads either.
constexpr char kOpenCvDirective[] = "%YAML:1.0";
constexpr char kYamlDirective[] = "%YAML 1.0";
constexpr double kRotationTolerance = 1e-6;  // |R^T R - I| of a rotation read back

// A matrix as OpenCV's map {rows, cols, dt, data} without the !!opencv-matrix tag.
void WriteMatrix(cv::FileStorage& fs, const std::string& name, int rows, int cols,
                 const double* row_major) {
  fs << name << "{"
     << "rows" << rows << "cols" << cols << "dt"
     << "d"
     << "data"
     << "[:";
  for (int i = 0; i < rows * cols; ++i) fs << row_major[i];
  fs << "]"
     << "}";
}

void WriteIntrinsics(cv::FileStorage& fs, const CameraModel& m) {
  fs << "image_width" << m.width_px << "image_height" << m.height_px;
  const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> k = m.K();
  WriteMatrix(fs, "camera_matrix", 3, 3, k.data());
  fs << "distortion_model"
     << "plumb_bob";
  const std::array<double, 5> d = m.distortion.ToArray();
  WriteMatrix(fs, "distortion_coefficients", 1, 5, d.data());
}

void WriteRigid(cv::FileStorage& fs, const std::string& r_name, const std::string& t_name,
                const Rigid3d& target_from_source) {
  const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> r = target_from_source.RotationMatrix();
  WriteMatrix(fs, r_name, 3, 3, r.data());
  WriteMatrix(fs, t_name, 3, 1, target_from_source.translation.data());
}

// Reading: every error names the file and the key.
class YamlReader {
 public:
  explicit YamlReader(std::string path) : path_(std::move(path)) {}

  Status Error(const std::string& key, const std::string& what) const {
    return ParseError(path_ + ": " + key + " " + what);
  }

  Expected<cv::Mat> Matrix(const cv::FileNode& parent, const std::string& prefix,
                           const std::string& key, int rows, int cols) const {
    const std::string field = prefix + key;
    const cv::FileNode node = parent[key];
    if (node.empty()) return Error(field, "is missing");
    // The size the file states is checked before OpenCV allocates it (rows: 99999, cols: 99999
    // would ask for 80 GB before the data is looked at).
    if (!node.isMap() || !node["rows"].isInt() || !node["cols"].isInt() ||
        static_cast<int>(node["rows"]) != rows || static_cast<int>(node["cols"]) != cols ||
        !node["data"].isSeq() || node["data"].size() != static_cast<size_t>(rows) * cols) {
      return Error(field, "must be a " + std::to_string(rows) + "x" + std::to_string(cols) +
                              " matrix {rows, cols, dt, data}");
    }
    cv::Mat m;
    try {
      node >> m;
    } catch (const cv::Exception& e) {
      return Error(field, std::string("is not a matrix (") + e.what() + ")");
    } catch (const std::exception& e) {
      return Error(field, std::string("is not a matrix (") + e.what() + ")");
    }
    if (m.rows != rows || m.cols != cols || m.type() != CV_64F) {
      return Error(field, "must be a " + std::to_string(rows) + "x" + std::to_string(cols) +
                              " matrix of doubles");
    }
    if (!cv::checkRange(m)) return Error(field, "has a number that is not finite");
    return m;
  }

  Expected<int> Int(const cv::FileNode& parent, const std::string& prefix,
                    const std::string& key) const {
    const cv::FileNode node = parent[key];
    if (node.empty() || !node.isInt()) return Error(prefix + key, "must be an integer");
    return static_cast<int>(node);
  }

  Expected<CameraModel> Intrinsics(const cv::FileNode& parent, const std::string& prefix) const {
    Expected<int> width = Int(parent, prefix, "image_width");
    if (!width.ok()) return width.status();
    Expected<int> height = Int(parent, prefix, "image_height");
    if (!height.ok()) return height.status();
    Expected<cv::Mat> k = Matrix(parent, prefix, "camera_matrix", 3, 3);
    if (!k.ok()) return k.status();
    Expected<cv::Mat> d = Matrix(parent, prefix, "distortion_coefficients", 1, 5);
    if (!d.ok()) return d.status();
    const cv::FileNode model_node = parent["distortion_model"];
    if (!model_node.isString() || static_cast<std::string>(model_node) != "plumb_bob") {
      return Error(prefix + "distortion_model", "must be plumb_bob");
    }
    const CameraModel m(*width, *height, k->at<double>(0, 0), k->at<double>(1, 1),
                        k->at<double>(0, 2), k->at<double>(1, 2),
                        BrownDistortion::FromArray(d->ptr<double>()));
    if (Status valid = m.Check(); !valid.ok()) return valid.WithContext(path_ + ": " + prefix);
    return m;
  }

  Expected<Rigid3d> Rigid(const cv::FileNode& parent, const std::string& prefix,
                          const std::string& r_key, const std::string& t_key) const {
    Expected<cv::Mat> r = Matrix(parent, prefix, r_key, 3, 3);
    if (!r.ok()) return r.status();
    Expected<cv::Mat> t = Matrix(parent, prefix, t_key, 3, 1);
    if (!t.ok()) return t.status();
    Eigen::Matrix3d rotation;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) rotation(i, j) = r->at<double>(i, j);
    const double error = (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).norm();
    if (!(error <= kRotationTolerance) || !(rotation.determinant() > 0.0)) {
      return Error(prefix + r_key,
                   "is not a rotation (|R^T R - I| = " + std::to_string(error) + ")");
    }
    return Rigid3d(rotation, Eigen::Vector3d(t->at<double>(0), t->at<double>(1), t->at<double>(2)));
  }

 private:
  std::string path_;
};

}  // namespace

Expected<std::string> OpenCvYamlText(const UnitCalibration& c) {
  ST_RETURN_IF_ERROR(c.Check());
  const std::string unit =
      c.unit_id == kInvalidNodeId ? std::string("unit") : "unit " + std::to_string(c.unit_id);
  if (!c.table_from_projector) {
    return InvalidArgumentError(unit +
                                ": no table_from_projector; the OpenCV export needs a unit "
                                "registered in a site");
  }
  if (!c.table_from_model) {
    return InvalidArgumentError(unit +
                                ": no table_from_model; the OpenCV export needs the "
                                "model's placement on the table");
  }
  // x_in_projector = projector_from_table * table_from_model * x_in_model.
  const Rigid3d projector_from_model = c.table_from_projector->Inverse() * *c.table_from_model;
  try {
    cv::FileStorage fs(
        ".yaml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
    fs << "format" << kOpenCvYamlFormat << "version" << kOpenCvYamlVersion;
    if (c.unit_id != kInvalidNodeId) fs << "unit_id" << static_cast<int>(c.unit_id);
    if (!c.source.empty()) fs << "source" << c.source;
    fs << "camera_name"
       << (c.unit_id == kInvalidNodeId ? std::string("projector")
                                       : "unit-" + std::to_string(c.unit_id) + "-projector");
    WriteIntrinsics(fs, c.projector);
    const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> identity =
        Eigen::Matrix<double, 3, 3, Eigen::RowMajor>::Identity();
    WriteMatrix(fs, "rectification_matrix", 3, 3, identity.data());
    Eigen::Matrix<double, 3, 4, Eigen::RowMajor> projection =
        Eigen::Matrix<double, 3, 4, Eigen::RowMajor>::Zero();
    projection.leftCols<3>() = c.projector.K();
    WriteMatrix(fs, "projection_matrix", 3, 4, projection.data());
    fs.writeComment(
        "x_in_projector = R x_in_model + T (metres); model: the glTF model's frame "
        "converted to z-up (docs/frames.md)");
    WriteRigid(fs, "R", "T", projector_from_model);
    fs << "camera"
       << "{";
    WriteIntrinsics(fs, c.camera);
    WriteRigid(fs, "projector_from_camera_R", "projector_from_camera_T_m", c.projector_from_camera);
    fs << "}";
    std::string text = fs.releaseAndGetString();
    if (text.rfind(kOpenCvDirective, 0) == 0) {
      text.replace(0, sizeof(kOpenCvDirective) - 1, kYamlDirective);
    }
    return text;
  } catch (const cv::Exception& e) {
    return InternalError(std::string("OpenCV YAML export: ") + e.what());
  }
}

Status WriteOpenCvYaml(const UnitCalibration& calibration, const std::string& path) {
  Expected<std::string> text = OpenCvYamlText(calibration);
  if (!text.ok()) return text.status().WithContext(path);
  return io::WriteTextFile(*text, path);
}

// The fields of a parsed file (below; cv::FileNode conversions may throw).
static Expected<OpenCvYamlCalibration> ParseOpenCvYamlRoot(const cv::FileStorage& fs,
                                                           const std::string& path);

Expected<OpenCvYamlCalibration> ReadOpenCvYaml(const std::string& path) {
  Expected<std::string> text = ReadInputFile(path, kMaxTextInputBytes, "kMaxTextInputBytes");
  if (!text.ok()) return IoError(text.status().message());  // the message names the path
  return ParseOpenCvYaml(*text, path);
}

Expected<OpenCvYamlCalibration> ParseOpenCvYaml(const std::string& text, const std::string& path) {
  if (text.find_first_not_of(" \t\r\n") == std::string::npos) {
    return ParseError(path + ": empty file, OpenCV YAML is expected");
  }
  cv::FileStorage fs;
  try {
    if (!fs.open(text,
                 cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML)) {
      return ParseError(path + ": not an OpenCV YAML file");
    }
  } catch (const cv::Exception& e) {
    return ParseError(path + ": not an OpenCV YAML file (" + e.what() + ")");
  } catch (const std::exception& e) {
    // OpenCV's parser lets standard exceptions through (a length_error from a crafted scalar,
    // found by fuzz_json_formats).
    return ParseError(path + ": not an OpenCV YAML file (" + e.what() + ")");
  }
  try {
    return ParseOpenCvYamlRoot(fs, path);
  } catch (const cv::Exception& e) {
    return ParseError(path + ": not an OpenCV YAML calibration (" + e.what() + ")");
  } catch (const std::exception& e) {
    return ParseError(path + ": not an OpenCV YAML calibration (" + e.what() + ")");
  }
}

static Expected<OpenCvYamlCalibration> ParseOpenCvYamlRoot(const cv::FileStorage& fs,
                                                           const std::string& path) {
  const YamlReader reader(path);
  const cv::FileNode root = fs.root();
  const cv::FileNode format = root["format"];
  if (!format.isString() || static_cast<std::string>(format) != kOpenCvYamlFormat) {
    return reader.Error("format", std::string("must be \"") + kOpenCvYamlFormat + "\"");
  }
  Expected<int> version = reader.Int(root, "", "version");
  if (!version.ok()) return version.status();
  if (*version != kOpenCvYamlVersion) {
    return reader.Error("version", "= " + std::to_string(*version) + " is not supported (" +
                                       std::to_string(kOpenCvYamlVersion) + ")");
  }
  OpenCvYamlCalibration out;
  if (!root["unit_id"].empty()) {
    Expected<int> unit_id = reader.Int(root, "", "unit_id");
    if (!unit_id.ok()) return unit_id.status();
    if (*unit_id < 0) return reader.Error("unit_id", "must be >= 0");
    out.unit_id = static_cast<NodeId>(*unit_id);
  }
  if (root["source"].isString()) out.source = static_cast<std::string>(root["source"]);
  Expected<CameraModel> projector = reader.Intrinsics(root, "");
  if (!projector.ok()) return projector.status();
  out.projector = *projector;
  Expected<Rigid3d> projector_from_model = reader.Rigid(root, "", "R", "T");
  if (!projector_from_model.ok()) return projector_from_model.status();
  out.projector_from_model = *projector_from_model;
  const cv::FileNode camera = root["camera"];
  if (!camera.empty()) {
    if (!camera.isMap()) return reader.Error("camera", "must be a map");
    Expected<CameraModel> model = reader.Intrinsics(camera, "camera.");
    if (!model.ok()) return model.status();
    out.camera = *model;
    Expected<Rigid3d> projector_from_camera =
        reader.Rigid(camera, "camera.", "projector_from_camera_R", "projector_from_camera_T_m");
    if (!projector_from_camera.ok()) return projector_from_camera.status();
    out.projector_from_camera = *projector_from_camera;
  }
  return out;
}

}  // namespace sandtable
