#include "common/io/mpcdi.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <map>
#include <set>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/base/file_io.h"
#include "common/io/image_file.h"
#include "common/io/mpcdi_xml.h"
#include "common/io/mpcdi_zip.h"

namespace sandtable {

namespace {

using mpcdi_internal::MpcdiFileRequest;

constexpr double kDegFromRad = 180.0 / M_PI;
constexpr double kRadFromDeg = M_PI / 180.0;
// Orthonormality of a written coordinate frame's axes (unit length, pairwise dot products).
constexpr double kAxisTolerance = 1e-6;
// Below this cos(pitch), yaw and roll turn about the same axis (gimbal lock).
constexpr double kGimbalCos = 1e-9;
// Everything inflated from one archive.
constexpr uint64_t kMaxMpcdiTotalBytes = uint64_t{1} << 30;

bool IsOneOf(const std::string& value, std::initializer_list<const char*> names) {
  return std::any_of(names.begin(), names.end(), [&](const char* n) { return value == n; });
}

bool IsFileSafeId(const std::string& id) {
  if (id.empty() || id.size() > 64 || id == "." || id == "..") return false;
  return std::all_of(id.begin(), id.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
           c == '_' || c == '-';
  });
}

bool IsMpcdiDate(const std::string& date) {
  // yyyy-MM-dd HH:mm:ss
  static constexpr char kPattern[] = "dddd-dd-dd dd:dd:dd";
  if (date.size() != sizeof(kPattern) - 1) return false;
  for (size_t i = 0; i < date.size(); ++i) {
    const bool digit = date[i] >= '0' && date[i] <= '9';
    if (kPattern[i] == 'd' ? !digit : date[i] != kPattern[i]) return false;
  }
  return true;
}

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char buffer[32];
  std::strftime(buffer, sizeof(buffer), "%Y-%m-%d %H:%M:%S", &utc);
  return buffer;
}

Status CheckBlendMap(const MpcdiBlendMap& map, const std::string& what, bool is_alpha) {
  if (map.width_px < 2 || map.height_px < 2) {
    return InvalidArgumentError(what + ": " + std::to_string(map.width_px) + "x" +
                                std::to_string(map.height_px) +
                                " px, a blend map needs at least 2x2 (MPCDI 3.7)");
  }
  ST_RETURN_IF_ERROR(io::CheckImageSize(map.width_px, map.height_px, what));
  if (map.values.size() != static_cast<size_t>(map.width_px) * map.height_px) {
    return InvalidArgumentError(what + ": " + std::to_string(map.values.size()) + " values for " +
                                std::to_string(map.width_px) + "x" + std::to_string(map.height_px) +
                                " px");
  }
  if (is_alpha && !(std::isfinite(map.gamma_embedded) && map.gamma_embedded > 0.0)) {
    return InvalidArgumentError(what + ": gamma_embedded = " + std::to_string(map.gamma_embedded) +
                                " must be finite and > 0");
  }
  return OkStatus();
}

Status CheckWarp(const MpcdiWarp& warp, const std::string& what, const std::string& profile) {
  if (warp.samples_x < 2 || warp.samples_y < 2 || warp.samples_x > kMaxMpcdiWarpSide ||
      warp.samples_y > kMaxMpcdiWarpSide ||
      int64_t{warp.samples_x} * warp.samples_y > kMaxMpcdiWarpSamples) {
    return InvalidArgumentError(what + ": " + std::to_string(warp.samples_x) + "x" +
                                std::to_string(warp.samples_y) +
                                " samples, a warp grid needs 2x2 (MPCDI 3.6) up to " +
                                "kMaxMpcdiWarpSide and kMaxMpcdiWarpSamples");
  }
  if (warp.samples.size() != static_cast<size_t>(warp.samples_x) * warp.samples_y) {
    return InvalidArgumentError(what + ": " + std::to_string(warp.samples.size()) +
                                " samples for a " + std::to_string(warp.samples_x) + "x" +
                                std::to_string(warp.samples_y) + " grid");
  }
  if (!IsOneOf(warp.interpolation, {"linear", "keystone", "smooth", "unknown"})) {
    return InvalidArgumentError(what + ": interpolation \"" + warp.interpolation +
                                "\" is not linear, keystone, smooth or unknown");
  }
  const bool needs_3d_tags = profile == "sl" || profile == "a3";
  if (!(warp.geometric_unit.empty() && !needs_3d_tags) &&
      !IsOneOf(warp.geometric_unit, {"mm", "cm", "dm", "m", "in", "ft", "yd", "unknown"})) {
    return InvalidArgumentError(what + ": geometric_unit \"" + warp.geometric_unit +
                                "\" is not mm, cm, dm, m, in, ft, yd or unknown");
  }
  if (!(warp.origin_of_3d_data.empty() && !needs_3d_tags) &&
      !IsOneOf(warp.origin_of_3d_data,
               {"centerOfMass", "idealEyePoint", "floorCenter", "unknown"})) {
    return InvalidArgumentError(what + ": origin_of_3d_data \"" + warp.origin_of_3d_data +
                                "\" is not centerOfMass, idealEyePoint, floorCenter or unknown");
  }
  if (profile == "sl" && warp.origin_of_3d_data == "idealEyePoint") {
    return InvalidArgumentError(what + ": origin_of_3d_data idealEyePoint is not allowed for " +
                                "profile sl (MPCDI 3.5.2)");
  }
  return OkStatus();
}

Status CheckFrustum(const MpcdiFrustum& f, const std::string& what) {
  const double values[] = {f.yaw_deg,        f.pitch_deg,    f.roll_deg,      f.right_angle_deg,
                           f.left_angle_deg, f.up_angle_deg, f.down_angle_deg};
  for (double v : values) {
    if (!std::isfinite(v)) return InvalidArgumentError(what + ": frustum angles must be finite");
  }
  for (double v : {f.right_angle_deg, f.left_angle_deg, f.up_angle_deg, f.down_angle_deg}) {
    if (std::abs(v) >= 90.0) {
      return InvalidArgumentError(what + ": frustum edge angle " + std::to_string(v) +
                                  " deg outside (-90, 90)");
    }
  }
  if (!(f.left_angle_deg < f.right_angle_deg) || !(f.down_angle_deg < f.up_angle_deg)) {
    return InvalidArgumentError(what + ": frustum needs leftAngle < rightAngle and " +
                                "downAngle < upAngle (MPCDI 2.3.1.1)");
  }
  return OkStatus();
}

Status CheckCoordinateFrame(const MpcdiCoordinateFrame& c, const std::string& what) {
  if (!c.position.allFinite() || !c.yaw_axis.allFinite() || !c.pitch_axis.allFinite() ||
      !c.roll_axis.allFinite()) {
    return InvalidArgumentError(what + ": coordinate frame values must be finite");
  }
  const Eigen::Vector3d axes[] = {c.yaw_axis, c.pitch_axis, c.roll_axis};
  for (int i = 0; i < 3; ++i) {
    if (std::abs(axes[i].norm() - 1.0) > kAxisTolerance ||
        std::abs(axes[i].dot(axes[(i + 1) % 3])) > kAxisTolerance) {
      return InvalidArgumentError(what + ": coordinate frame axes (yaw, pitch, roll) must be " +
                                  "orthonormal unit vectors (MPCDI 2.3.1.2)");
    }
  }
  return OkStatus();
}

Eigen::Matrix3d Basis(const std::optional<MpcdiCoordinateFrame>& frame) {
  Eigen::Matrix3d basis = Eigen::Matrix3d::Identity();
  if (frame) {
    basis.col(0) = frame->pitch_axis;  // the viewer's x (right)
    basis.col(1) = frame->yaw_axis;    // the viewer's y (down)
    basis.col(2) = frame->roll_axis;   // the viewer's z (ahead)
  }
  return basis;
}

Expected<std::string> EncodeBlendMapPng(const MpcdiBlendMap& map, const std::string& what) {
  std::vector<unsigned char> png;
  try {
    const cv::Mat image(map.height_px, map.width_px, CV_8UC1,
                        const_cast<uint8_t*>(map.values.data()));
    if (!cv::imencode(".png", image, png)) return InternalError(what + ": PNG encoding failed");
  } catch (const cv::Exception& e) {
    return InternalError(what + ": PNG encoding failed (OpenCV: " + e.what() + ")");
  }
  return std::string(reinterpret_cast<const char*>(png.data()), png.size());
}

// An alpha or beta map PNG, as declared: componentDepth 1, bitDepth 8 or 16 (16-bit values are
// rounded to 8 bits).
Status DecodeBlendMapPng(std::string_view bytes, const MpcdiFileRequest& request,
                         const std::string& what, MpcdiBlendMap* map) {
  if (request.component_depth != 1) {
    return InvalidArgumentError(what + ": componentDepth " +
                                std::to_string(request.component_depth) +
                                " is not supported (blend maps are read as 1 component)");
  }
  if (request.bit_depth != 8 && request.bit_depth != 16) {
    return InvalidArgumentError(what + ": bitDepth " + std::to_string(request.bit_depth) +
                                " is not supported in a PNG (8 or 16)");
  }
  const std::optional<cv::Size> header = io::ImageHeaderSize(bytes);
  if (!header || bytes.size() < 8 || bytes.substr(1, 3) != "PNG") {
    return ParseError(what + ": not a PNG file");
  }
  ST_RETURN_IF_ERROR(io::CheckImageSize(header->width, header->height, what));
  cv::Mat image;
  try {
    const cv::Mat raw(1, static_cast<int>(bytes.size()), CV_8U, const_cast<char*>(bytes.data()));
    image = cv::imdecode(raw, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return ParseError(what + ": PNG cannot be decoded (OpenCV: " + e.what() + ")");
  }
  if (image.empty()) return ParseError(what + ": PNG cannot be decoded");
  if (image.channels() != 1) {
    return ParseError(what + ": PNG has " + std::to_string(image.channels()) +
                      " channels, componentDepth says 1");
  }
  const int depth_bits = image.depth() == CV_8U ? 8 : image.depth() == CV_16U ? 16 : 0;
  if (depth_bits != request.bit_depth) {
    return ParseError(what + ": PNG holds " + std::to_string(depth_bits) +
                      "-bit samples, bitDepth says " + std::to_string(request.bit_depth));
  }
  if (depth_bits == 16) image.convertTo(image, CV_8U, 255.0 / 65535.0);  // rounds
  map->width_px = image.cols;
  map->height_px = image.rows;
  map->values.resize(static_cast<size_t>(image.cols) * image.rows);
  for (int r = 0; r < image.rows; ++r) {
    std::memcpy(map->values.data() + static_cast<size_t>(r) * image.cols, image.ptr<uint8_t>(r),
                static_cast<size_t>(image.cols));
  }
  return OkStatus();
}

// Loads every file the descriptor names into the site; `load(name)` returns a file's bytes.
template <typename Loader>
Status LoadFiles(const std::vector<MpcdiFileRequest>& files, const std::string& source,
                 const Loader& load, MpcdiSite* site) {
  for (const MpcdiFileRequest& request : files) {
    Expected<std::string> bytes = load(request);
    if (!bytes.ok()) return bytes.status();
    const std::string what = source + ": " + request.path + " (" + request.element + ")";
    MpcdiRegion& region = site->regions[request.region];
    switch (request.kind) {
      case MpcdiFileRequest::Kind::kWarp: {
        Expected<MpcdiWarp> grid = DecodeMpcdiPfm(*bytes, what);
        if (!grid.ok()) return grid.status();
        region.warp->samples_x = grid->samples_x;
        region.warp->samples_y = grid->samples_y;
        region.warp->samples = std::move(grid->samples);
        break;
      }
      case MpcdiFileRequest::Kind::kAlpha:
        ST_RETURN_IF_ERROR(DecodeBlendMapPng(*bytes, request, what, &*region.alpha));
        break;
      case MpcdiFileRequest::Kind::kBeta:
        ST_RETURN_IF_ERROR(DecodeBlendMapPng(*bytes, request, what, &*region.beta));
        break;
    }
  }
  return OkStatus();
}

// The descriptor entry of an archive: mpcdi.xml, else mpacs.xml, else the only *.xml entry.
Expected<const io::ZipEntry*> DescriptorEntry(const std::vector<io::ZipEntry>& entries,
                                              const std::string& path) {
  for (const char* name : {kMpcdiXmlEntry, "mpacs.xml"}) {
    for (const io::ZipEntry& entry : entries) {
      if (entry.name == name) return &entry;
    }
  }
  std::vector<const io::ZipEntry*> xml;
  for (const io::ZipEntry& entry : entries) {
    std::string lower = entry.name;
    std::transform(lower.begin(), lower.end(), lower.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (lower.size() > 4 && lower.compare(lower.size() - 4, 4, ".xml") == 0) {
      xml.push_back(&entry);
    }
  }
  if (xml.size() == 1) return xml.front();
  return ParseError(path + ": the archive holds no mpcdi.xml and " + std::to_string(xml.size()) +
                    " other .xml entries (exactly one is needed to take it as the descriptor)");
}

}  // namespace

Status MpcdiSite::CheckForWriting() const {
  if (!IsOneOf(profile, {"2d", "3d", "a3", "sl"})) {
    return InvalidArgumentError("MPCDI: profile \"" + profile + "\" is not 2d, 3d, a3 or sl");
  }
  if (level < 1 || level > 4) {
    return InvalidArgumentError("MPCDI: level " + std::to_string(level) + " is not 1-4");
  }
  if (!date.empty() && !IsMpcdiDate(date)) {
    return InvalidArgumentError("MPCDI: date \"" + date + "\" is not yyyy-MM-dd HH:mm:ss");
  }
  if (buffer_id.empty()) return InvalidArgumentError("MPCDI: buffer_id is empty");
  for (int r : {buffer_x_resolution_px, buffer_y_resolution_px}) {
    if (r < 0 || r > kMaxMpcdiResolution_px) {
      return InvalidArgumentError("MPCDI: buffer resolution " + std::to_string(r) +
                                  " px outside [0, kMaxMpcdiResolution_px]");
    }
  }
  if (regions.empty() || regions.size() > static_cast<size_t>(kMaxMpcdiRegions)) {
    return InvalidArgumentError("MPCDI: " + std::to_string(regions.size()) +
                                " regions, 1 to kMaxMpcdiRegions are written");
  }
  std::set<std::string> ids;
  const std::string* origin = nullptr;
  for (const MpcdiRegion& region : regions) {
    const std::string what = "MPCDI region \"" + region.id + "\"";
    if (!IsFileSafeId(region.id)) {
      return InvalidArgumentError(what + ": id must be 1-64 characters of [A-Za-z0-9._-] " +
                                  "(it names the region's files)");
    }
    if (!ids.insert(region.id).second) return InvalidArgumentError(what + ": id given twice");
    for (int r : {region.x_resolution_px, region.y_resolution_px}) {
      if (r < 1 || r > kMaxMpcdiResolution_px) {
        return InvalidArgumentError(what + ": resolution " + std::to_string(r) +
                                    " px outside [1, kMaxMpcdiResolution_px]");
      }
    }
    if (!std::isfinite(region.x) || !std::isfinite(region.y) || !std::isfinite(region.x_size) ||
        !std::isfinite(region.y_size) || region.x_size <= 0.0 || region.y_size <= 0.0) {
      return InvalidArgumentError(what + ": x, y must be finite and xsize, ysize finite and > 0");
    }
    if (profile == "3d" || profile == "sl") {
      if (!region.frustum)
        return InvalidArgumentError(what + ": profile " + profile +
                                    " needs a frustum (MPCDI 3.5.2)");
      ST_RETURN_IF_ERROR(CheckFrustum(*region.frustum, what));
    }
    if (profile == "sl" && !region.coordinate_frame) {
      return InvalidArgumentError(what + ": profile sl needs a coordinate frame (MPCDI 3.5.2)");
    }
    if (region.coordinate_frame) {
      ST_RETURN_IF_ERROR(CheckCoordinateFrame(*region.coordinate_frame, what));
    }
    if (!region.warp) return InvalidArgumentError(what + ": no warp (every fileset has one)");
    ST_RETURN_IF_ERROR(CheckWarp(*region.warp, what + " warp", profile));
    if (origin != nullptr && *origin != region.warp->origin_of_3d_data) {
      return InvalidArgumentError(what + ": origin_of_3d_data differs from the other regions' " +
                                  "(MPCDI 3.5.2: one origin)");
    }
    origin = &region.warp->origin_of_3d_data;
    if (!region.alpha) {
      return InvalidArgumentError(what + ": no alpha map (every fileset has one)");
    }
    ST_RETURN_IF_ERROR(CheckBlendMap(*region.alpha, what + " alpha map", true));
    if (region.beta) ST_RETURN_IF_ERROR(CheckBlendMap(*region.beta, what + " beta map", false));
  }
  return OkStatus();
}

const MpcdiRegion* MpcdiSite::FindRegion(std::string_view id) const {
  for (const MpcdiRegion& region : regions) {
    if (region.id == id) return &region;
  }
  return nullptr;
}

Eigen::Matrix3d MpcdiWorldFromViewer(const MpcdiFrustum& frustum,
                                     const std::optional<MpcdiCoordinateFrame>& frame) {
  // Yaw first about the viewer's y, then pitch about the turned x, then roll about the new z:
  // intrinsic rotations, so the matrices multiply in that order.
  return Basis(frame) *
         Eigen::AngleAxisd(frustum.yaw_deg * kRadFromDeg, Eigen::Vector3d::UnitY()).matrix() *
         Eigen::AngleAxisd(frustum.pitch_deg * kRadFromDeg, Eigen::Vector3d::UnitX()).matrix() *
         Eigen::AngleAxisd(frustum.roll_deg * kRadFromDeg, Eigen::Vector3d::UnitZ()).matrix();
}

void SetMpcdiOrientation(const Eigen::Matrix3d& world_from_viewer,
                         const std::optional<MpcdiCoordinateFrame>& frame, MpcdiFrustum* frustum) {
  // M = Ry(a) Rx(b) Rz(c) =
  //   [ ca cc + sa sb sc   -ca sc + sa sb cc   sa cb ]
  //   [ cb sc              cb cc               -sb   ]
  //   [ -sa cc + ca sb sc  sa sc + ca sb cc    ca cb ]
  const Eigen::Matrix3d m = Basis(frame).transpose() * world_from_viewer;
  const double sb = std::clamp(-m(1, 2), -1.0, 1.0);
  const double b = std::asin(sb);
  double a = 0.0, c = 0.0;
  if (std::cos(b) > kGimbalCos) {
    a = std::atan2(m(0, 2), m(2, 2));
    c = std::atan2(m(1, 0), m(1, 1));
  } else {
    // cb = 0: with c = 0, m(0, 0) = ca and m(0, 1) = sa sb.
    a = std::atan2(m(0, 1) * sb, m(0, 0));
  }
  frustum->yaw_deg = a * kDegFromRad;
  frustum->pitch_deg = b * kDegFromRad;
  frustum->roll_deg = c * kDegFromRad;
}

Expected<std::string> EncodeMpcdiArchive(const MpcdiSite& site) {
  ST_RETURN_IF_ERROR(site.CheckForWriting());
  std::vector<io::ZipEntry> entries;
  entries.push_back({kMpcdiXmlEntry, mpcdi_internal::EncodeMpcdiXml(
                                         site, site.date.empty() ? UtcNow() : site.date)});
  for (const MpcdiRegion& region : site.regions) {
    entries.push_back({mpcdi_internal::WarpFileName(region.id), EncodeMpcdiPfm(*region.warp)});
    Expected<std::string> alpha = EncodeBlendMapPng(*region.alpha, region.id + " alpha map");
    if (!alpha.ok()) return alpha.status();
    entries.push_back({mpcdi_internal::AlphaFileName(region.id), std::move(*alpha)});
    if (region.beta) {
      Expected<std::string> beta = EncodeBlendMapPng(*region.beta, region.id + " beta map");
      if (!beta.ok()) return beta.status();
      entries.push_back({mpcdi_internal::BetaFileName(region.id), std::move(*beta)});
    }
  }
  return io::EncodeZipArchive(entries);
}

Status WriteMpcdi(const std::string& path, const MpcdiSite& site) {
  Expected<std::string> archive = EncodeMpcdiArchive(site);
  if (!archive.ok()) return archive.status().WithContext(path);
  return WriteFileAtomically(path, *archive);
}

Expected<MpcdiSite> ReadMpcdi(const std::string& path) {
  Expected<std::string> bytes = ReadInputFile(path, kMaxMpcdiFileBytes, "kMaxMpcdiFileBytes");
  if (!bytes.ok()) return bytes.status();
  if (io::LooksLikeZip(*bytes)) {
    io::ZipReadLimits limits;
    limits.max_entry_bytes = kMaxMpcdiEntryBytes;
    limits.max_total_bytes = kMaxMpcdiTotalBytes;
    Expected<std::vector<io::ZipEntry>> entries = io::DecodeZipArchive(*bytes, path, limits);
    if (!entries.ok()) return entries.status();
    Expected<const io::ZipEntry*> xml_entry = DescriptorEntry(*entries, path);
    if (!xml_entry.ok()) return xml_entry.status();
    const std::string source = path + ": " + (*xml_entry)->name;
    Expected<mpcdi_internal::ParsedMpcdiXml> parsed =
        mpcdi_internal::ParseMpcdiXml((*xml_entry)->bytes, source);
    if (!parsed.ok()) return parsed.status();
    std::map<std::string_view, const std::string*> by_name;
    for (const io::ZipEntry& entry : *entries) by_name[entry.name] = &entry.bytes;
    auto load = [&](const MpcdiFileRequest& request) -> Expected<std::string> {
      const auto it = by_name.find(request.path);
      if (it == by_name.end()) {
        return ParseError(source + ": " + request.element + ": path \"" + request.path +
                          "\" names no entry of the archive");
      }
      return *it->second;
    };
    ST_RETURN_IF_ERROR(LoadFiles(parsed->files, path, load, &parsed->site));
    return std::move(parsed->site);
  }
  if (bytes->size() > kMaxTextInputBytes) {
    return InvalidArgumentError(path + ": " + std::to_string(bytes->size()) +
                                " bytes of XML, over kMaxTextInputBytes");
  }
  Expected<mpcdi_internal::ParsedMpcdiXml> parsed = mpcdi_internal::ParseMpcdiXml(*bytes, path);
  if (!parsed.ok()) return parsed.status();
  // A bare descriptor: its files lie beside it (file names are plain, checked by the parser).
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  auto load = [&](const MpcdiFileRequest& request) -> Expected<std::string> {
    Expected<std::string> file =
        ReadInputFile(folder / request.path, kMaxMpcdiEntryBytes, "kMaxMpcdiEntryBytes");
    if (!file.ok()) return file.status().WithContext(path + ": " + request.element);
    return file;
  };
  ST_RETURN_IF_ERROR(LoadFiles(parsed->files, path, load, &parsed->site));
  return std::move(parsed->site);
}

}  // namespace sandtable
