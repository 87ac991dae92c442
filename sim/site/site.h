// Site: the TRUE rig of a simulated installation (what the world knows and nodes never see).
//
// Frames: table frame (origin on the table top, +z up, metres). Projector and camera frames are
// OpenCV (x right, y down, z forward). table_from_projector maps x_in_projector to x_in_table;
// a unit's camera is mounted on its projector: projector_from_camera.
// Photometry (monochrome world):
//   projector: a frame value v in [0, 255] emits (black_level + (1 - black_level) (v/255)^gamma)
//   times peak_luminance_at_1m_nits, which is the luminance of a white (albedo 1) Lambertian
//   surface facing the projector 1 m away under a full-white frame; elsewhere the luminance is
//   that times albedo cos(theta) / d^2 (d in m, theta the incidence angle).
//   camera: linear signal s = L exposure_s / saturation_nit_s (1 = full scale), photon noise
//   with full_well_e electrons at full scale, Gaussian read noise read_noise_dn (in output DN of
//   the linear signal), then the encoding s^(1/gamma), quantised to bit_depth bits.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "sim/site/device_timing.h"

namespace sandtable::sim {

// Limits of a site (Site::Check refuses past them, naming the limit; the site parser refuses a
// units array longer than kMaxSiteUnits before reading one unit).
// Units in one site (ids are also bounded: [0, 2^30]).
inline constexpr size_t kMaxSiteUnits = 256;
// Each side of a projector or camera image, px, and its area (4096 x 4096 = 16 Mpx: the world
// holds a transport map of ~30 bytes plus 32 bytes per lit projector per camera pixel).
inline constexpr int kMaxSiteImageSide_px = 8192;
inline constexpr int64_t kMaxSiteImagePixels = int64_t{4096} * 4096;
// Every translation of a site (table_from_projector, projector_from_camera): finite and each
// coordinate within this, m (as kMaxSceneCoordinate_m of a scene).
inline constexpr double kMaxSiteCoordinate_m = 1e4;

struct ProjectorSpec {
  CameraModel model;  // resolution, intrinsics, Brown distortion
  Rigid3d table_from_projector;
  double gamma = 2.2;
  double peak_luminance_at_1m_nits = 2000.0;
  double black_level = 0.002;  // fraction of peak emitted for a black frame, in [0, 1)
  // Defocus (optional): 0 = always in focus. Blur circle diameter in projector pixels at
  // distance d: fx_px * aperture_diameter_m * |d - focus_distance_m| / (d * focus_distance_m).
  double focus_distance_m = 0.0;
  double aperture_diameter_m = 0.0;
};

struct CameraSpec {
  CameraModel model;
  Rigid3d projector_from_camera;
  double read_noise_dn = 0.5;
  double exposure_s = 0.005;
  double saturation_nit_s = 10.0;  // luminance x exposure that reaches full scale
  double full_well_e = 10000.0;    // electrons at full scale (photon noise); 0 = no shot noise
  double gamma = 1.0;              // output encoding s^(1/gamma)
  int bit_depth = 8;               // 1..16
  double MaxDn() const { return static_cast<double>((1 << bit_depth) - 1); }
};

struct UnitSpec {
  NodeId id = kInvalidNodeId;
  std::string name;
  ProjectorSpec projector;
  std::optional<CameraSpec> camera;
  DeviceTiming timing;  // "timing" in the file; absent: the ideal devices
};

struct TableSpec {
  bool is_disc = true;
  double diameter_m = 1.524;                           // disc
  Eigen::Vector2d size_m = Eigen::Vector2d(2.0, 1.5);  // rectangle (x, y), centred
  bool Contains(const Eigen::Vector2d& xy_in_table_m) const;
};

struct Site {
  std::string name;
  TableSpec table;
  double ambient_luminance_nits = 5.0;  // luminance of a white surface under ambient light alone
  std::vector<UnitSpec> units;

  // OK, or the first problem, naming unit and field: "unit 2 (p2): projector.fx_px = -3 must
  // be > 0", "unit 1: projector sees nothing of the table ...", "units[3]: duplicate id 1",
  // or the limit: "site: 2000 units, more than kMaxSiteUnits = 256".
  Status Check() const;

  const UnitSpec* FindUnit(NodeId id) const;
  Rigid3d TableFromCamera(const UnitSpec& unit) const {
    return unit.projector.table_from_projector * unit.camera->projector_from_camera;
  }
};

// table_from_device for a device at `eye_in_table_m` looking at `target_in_table_m`, with the
// image's "up" (-y) as close as possible to `up_hint_in_table`. OpenCV axes. INVALID_ARGUMENT
// when eye == target or the view direction is parallel to up_hint.
Expected<Rigid3d> TableFromDeviceLookAt(const Eigen::Vector3d& eye_in_table_m,
                                        const Eigen::Vector3d& target_in_table_m,
                                        const Eigen::Vector3d& up_hint_in_table);

}  // namespace sandtable::sim
