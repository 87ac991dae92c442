// MPCDI (VESA Multiple Projection Common Data Interchange): the site export `site.mpcdi`
// (profile "sl", shader lamps) and a reader for MPCDI files of other tools. docs/file-formats.md
// ("MPCDI export") says the same for users.
//
// Checked against (names, required tags, conventions):
//  * the VESA MPCDI Standard version 1a (2013-11-11) and version 2.0 (2015-05-19), the PDFs in
//    github.com/drwrose/PyMPCDI doc/ (commits fe2f80f1, f3253ed5): sections 2.3.1 (frustum,
//    coordinate frame), 3.3-3.5 (ZIP container, profiles and levels, mpcdi.xml), 3.6 (PFM warp),
//    3.7 (PNG blend maps);
//  * the VESA/Scalable Display reference library (github.com/scaredyfish/MPCDI 1ddbc9ab):
//    src/IO/mpcdiXMLStrings.h, mpcdiWriterIntern.cpp, mpcdiReaderIntern.cpp, mpcdiPfmIO.cpp,
//    src/Container/mpcdiProfile.cpp (ValidateProfile);
//  * Christie's notes on the de-facto use of frustum and coordinateFrame
//    (github.com/tvaneerd/mpcdi MPCDI_explained.md) and PyMPCDI's PFM grid layout;
//  * the two real files in ../shared/data/mpcdi (Moment Factory's bare XML, SGCT's archives).
//
// What WriteMpcdi writes (MPCDI 1.0 names, spelled as the 1a standard's XML example and the
// reference library spell them; the standard makes tag and attribute names case-insensitive):
//   mpcdi.xml: <MPCDI profile="sl" level="1" date="yyyy-MM-dd HH:mm:ss" version="1.0">
//     <display><buffer id Xresolution Yresolution> one <region id Xresolution Yresolution x y
//     xsize ysize> per projector, each with <frustum> (yaw pitch roll rightAngle leftAngle
//     upAngle downAngle, degrees) and <coordinateFrame> (posx..posz, yawx..z, pitchx..z,
//     rollx..z)</display>
//     <files> one <fileset region=ID> per region: <geometryWarpFile> (path geometricUnit
//     interpolation originOf3DData) and <alphaMap> (path componentDepth bitDepth
//     gammaEmbedded), <betaMap> (path componentDepth bitDepth) when given</files>
//   GeometryWarpFile-ID.pfm, AlphaMap-ID.png (and BetaMap-ID.png): the reference library's
//   file names.
// Level 1 of profile sl: per-pixel 3D geometry allowed, lens distortion not a separate map (it
// is in the warp, see below), so no distortionMap (the standard asks for one from level 3; the
// reference library's ValidateProfile asks for one at every level and would refuse these files,
// its reader reads them). One buffer holding one region per projector, as Christie's Mystique
// writes sl files and the reference library's ValidateProfile demands (one buffer for 3d/sl);
// the standard's text says one region per buffer for sl, a rule the de-facto files do not keep.
//
// Conventions (the standard's viewer frame is the OpenCV device frame: x right, y down,
// z ahead; docs/frames.md):
//  * Frustum angles, degrees (rightAngle, upAngle > 0 and leftAngle, downAngle < 0 while the
//    principal point lies on the image): the tangent of each is the normalized image coordinate
//    of that image edge, y negated (up is -y): rightAngle = atan((width_px - 0.5 - cx_px) /
//    fx_px), upAngle = atan((cy_px + 0.5) / fy_px) (pixel-centre convention, the ideal
//    pinhole's; lens distortion lives in the warp).
//  * Orientation: world_from_viewer = C * Ry(yaw) * Rx(pitch) * Rz(roll): yaw first (about the
//    viewer's y axis, so + turns right), then pitch (about the turned x axis, + looks up), then
//    roll (about the viewing axis, + lowers the right side), each a right-handed rotation in
//    the viewer frame; C = [pitch_axis | yaw_axis | roll_axis] (columns) is the coordinate
//    frame's basis: the world directions of the zero-rotation viewer's right, down and ahead.
//    Standard 1a 2.3.1 (yaw "to the right", pitch "upwards", roll "clockwise", yaw first),
//    Christie's notes, and the Moment Factory file (all six regions look at the centre under
//    this reading, a test pins it) agree. Without a coordinateFrame C is the identity.
//  * Our export: C is the table frame read as Christie's "surveyor" frame (table +z up,
//    +y ahead, +x right): yaw_axis (0, 0, -1), pitch_axis (1, 0, 0), roll_axis (0, 1, 0), the
//    same for every region; pos = the projector's optical centre in the table frame, metres;
//    yaw/pitch/roll = table_from_projector's rotation (mpcdi_builder.h).
//  * Warp grid (standard 3.6, "fill layout"): samples_x x samples_y samples spread evenly over
//    the region, sample (i, j)'s centre at normalized ((i + 0.5) / samples_x,
//    (j + 0.5) / samples_y) of the region (PyMPCDI reads it so), i.e. projector pixel
//    u = (i + 0.5) * width_px / samples_x - 0.5 (OpenCV pixel centres). For sl and a3 each sample
//    holds the 3D surface point (x, y, z) in the world frame in `geometric_unit`; NaN marks a
//    sample that lights nothing. For 2d and 3d profiles it holds (u, v, error) in [0, 1] as the
//    file has them (SGCT's archives: error NaN). MpcdiWarp::samples is row-major, top row first.
//  * PFM (standard 3.6.1, netpbm): "PF\n<w> <h>\n-1.000000\n" then float32 RGB, little-endian
//    (scale < 0); rows stored bottom row first as netpbm defines them and the reference
//    library's PfmIO writes and reads them. (SGCT's reader takes the first stored row as the
//    top one; for its archives our rows are therefore upside down relative to SGCT's use.)
//  * Blend maps: 8-bit grey PNG, componentDepth 1, bitDepth 8; gammaEmbedded 1.0 (linear).
//
// What ReadMpcdi accepts: a ZIP archive (detected by its "PK" signature) holding mpcdi.xml (else
// mpacs.xml, which the reference library also reads, else its only *.xml entry, as in SGCT's
// archives), or a bare mpcdi XML file (Moment Factory writes `.mpcdi.xml`), whose files are
// then read from the XML's folder. Versions 1.x and 2.x; `level` (1.x) or `geometry` (2.x) for
// the level; tag and attribute names matched case-insensitively (the standard's rule, needed for
// Xresolution/xResolution/xSize); a UTF-8 BOM and CRLF; an empty <alphaMap/> (SGCT) is no alpha
// map; <distortionMap> and <extensionSet> are skipped. Required: MPCDI profile, version and
// level/geometry; display with exactly one buffer (more are refused as unsupported) with an id;
// each region's id, Xresolution, Yresolution, x, y, xsize, ysize; frustum (3d, sl) and
// coordinateFrame (sl) with all their tags; in a fileset: region naming a region,
// geometryWarpFile with path (and geometricUnit, originOf3DData for a3, sl), an alphaMap or
// betaMap with a path also needs componentDepth and bitDepth (and gammaEmbedded for alpha).
// The input is untrusted: every error is a Status naming the file, the archive entry and the
// element or attribute ("site.mpcdi: mpcdi.xml: MPCDI/display/buffer[id=0]/region[id=unit-3]
// (line 5): attribute xsize missing"); sizes are bounded before allocation (limits below,
// zip limits in mpcdi_zip.h, image limits in image_file.h). Codes: NOT_FOUND (missing file),
// IO_ERROR (unreadable), PARSE_ERROR (malformed ZIP, XML, PFM or PNG, missing or mistyped tag
// or attribute), INVALID_ARGUMENT (a value out of range, over a limit, or not supported).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"

namespace sandtable {

inline constexpr char kMpcdiProfileShaderLamps[] = "sl";
inline constexpr char kMpcdiXmlEntry[] = "mpcdi.xml";

// Limits of the reader (and of what the writer accepts).
inline constexpr uint64_t kMaxMpcdiFileBytes = uint64_t{512} << 20;   // the .mpcdi or .xml file
inline constexpr uint64_t kMaxMpcdiEntryBytes = uint64_t{256} << 20;  // one file in it
inline constexpr int kMaxMpcdiRegions = 256;
inline constexpr int kMaxMpcdiResolution_px = 65536;  // Xresolution, Yresolution
inline constexpr int kMaxMpcdiWarpSide = 16384;       // PFM width or height, samples
inline constexpr int64_t kMaxMpcdiWarpSamples = int64_t{4096} * 4096;  // PFM width x height

struct MpcdiFrustum {
  double yaw_deg = 0.0, pitch_deg = 0.0, roll_deg = 0.0;
  double right_angle_deg = 0.0, left_angle_deg = 0.0;  // right > left
  double up_angle_deg = 0.0, down_angle_deg = 0.0;     // up > down
};

struct MpcdiCoordinateFrame {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();           // posx, posy, posz
  Eigen::Vector3d yaw_axis = Eigen::Vector3d(0.0, 0.0, -1.0);   // the viewer's down (+y)
  Eigen::Vector3d pitch_axis = Eigen::Vector3d(1.0, 0.0, 0.0);  // the viewer's right (+x)
  Eigen::Vector3d roll_axis = Eigen::Vector3d(0.0, 1.0, 0.0);   // the viewer's ahead (+z)
};

struct MpcdiWarp {
  int samples_x = 0, samples_y = 0;
  std::vector<Eigen::Vector3f> samples;  // samples_x * samples_y, row-major, top row first
  std::string interpolation = "linear";  // linear, keystone, smooth, unknown; empty: not given
  std::string geometric_unit = "m";      // mm, cm, dm, m, in, ft, yd, unknown; empty: not given
  std::string origin_of_3d_data = "unknown";  // centerOfMass, idealEyePoint, floorCenter, unknown
};

// An alpha or beta map: 8-bit grey, row-major, top row first (255 = 1.0).
struct MpcdiBlendMap {
  int width_px = 0, height_px = 0;
  std::vector<uint8_t> values;  // width_px * height_px
  double gamma_embedded = 1.0;  // alpha maps only (1.0: linear)
};

struct MpcdiRegion {
  std::string id;  // written into file names: [A-Za-z0-9._-], 1-64 characters, for writing
  int x_resolution_px = 0, y_resolution_px = 0;
  double x = 0.0, y = 0.0, x_size = 1.0, y_size = 1.0;   // normalized buffer coordinates
  std::optional<MpcdiFrustum> frustum;                   // required for 3d, sl
  std::optional<MpcdiCoordinateFrame> coordinate_frame;  // required for sl
  std::optional<MpcdiWarp> warp;
  std::optional<MpcdiBlendMap> alpha;
  std::optional<MpcdiBlendMap> beta;
};

struct MpcdiSite {
  std::string profile = kMpcdiProfileShaderLamps;  // 2d, 3d, a3, sl (read: lower-cased)
  int level = 1;                                   // 1-4 (2.x files: their geometry level)
  std::string version;  // as read ("1.0", "2.0"); WriteMpcdi always writes "1.0"
  std::string date;     // "yyyy-MM-dd HH:mm:ss"; empty: WriteMpcdi writes the UTC time now
  std::string buffer_id = "0";
  int buffer_x_resolution_px = 0, buffer_y_resolution_px = 0;  // 0: not given
  std::vector<MpcdiRegion> regions;

  // What WriteMpcdi requires: a known profile, level 1-4, a date of the standard's form or
  // none, 1-kMaxMpcdiRegions regions with unique file-safe ids and resolutions in
  // [1, kMaxMpcdiResolution_px], finite normalized extents; a frustum (3d, sl; right > left,
  // up > down, all within (-90, 90) degrees) and an orthonormal coordinate frame (sl); every
  // region a warp (at least 2x2 samples, within the limits, known unit/origin/interpolation
  // names, never idealEyePoint for sl, one origin for all) and an alpha map (at least 2x2 px,
  // within image_file.h's limits). INVALID_ARGUMENT naming the region and field.
  Status CheckForWriting() const;

  const MpcdiRegion* FindRegion(std::string_view id) const;
};

// world_from_viewer (the viewer frame: x right, y down, z ahead) of a frustum's yaw, pitch and
// roll in a coordinate frame's basis (the identity basis without one); see the convention above.
Eigen::Matrix3d MpcdiWorldFromViewer(const MpcdiFrustum& frustum,
                                     const std::optional<MpcdiCoordinateFrame>& frame);
// The inverse: sets frustum->yaw_deg, pitch_deg, roll_deg so that MpcdiWorldFromViewer gives
// `world_from_viewer` (a rotation). pitch in [-90, 90]; at pitch = +-90 (looking along the
// yaw axis) roll is 0 and yaw carries the whole turn.
void SetMpcdiOrientation(const Eigen::Matrix3d& world_from_viewer,
                         const std::optional<MpcdiCoordinateFrame>& frame, MpcdiFrustum* frustum);

// PFM codec of a warp grid (the convention above). Decode: PARSE_ERROR for a bad header, a size
// that the data does not match, or a greyscale "Pf" map; INVALID_ARGUMENT over the limits.
std::string EncodeMpcdiPfm(const MpcdiWarp& warp);
Expected<MpcdiWarp> DecodeMpcdiPfm(std::string_view bytes, std::string_view source);

// The .mpcdi archive's bytes (CheckForWriting first), and the file, replaced all or nothing
// (WriteFileAtomically).
Expected<std::string> EncodeMpcdiArchive(const MpcdiSite& site);
Status WriteMpcdi(const std::string& path, const MpcdiSite& site);

// A .mpcdi archive or a bare mpcdi XML file (see above).
Expected<MpcdiSite> ReadMpcdi(const std::string& path);

}  // namespace sandtable
