// What the scanned table shows that the glTF model does not, per building: present, moved (by
// how much), missing, unobserved; and structure on the table that no building of the model
// explains ("present but not in the model").
//
// Inputs: the model (common/scene Scene in its own z-up frame, table top at z = 0), the scanned
// surface points in the cluster's table frame (metres, the cluster's scale already fixed) and
// the found table_from_model (model_registration.h). The model's placement comes from the
// whole scene; a few changed buildings do not move it (its ICP drops pairs beyond 1 cm).
// Method, in the model frame:
//   1. Parts: the model's triangles that rise above structure_height_m, grouped by shared
//      vertices (welded at 10 um) and then by overlapping footprints: one part per building.
//      The rest (the table, anything lower) is ground.
//   2. Footprint raster (cell_m): each cell holds the part whose upward-facing surface covers
//      its centre (the highest), so a scan point falls into one part's footprint or none. Scan
//      points are "up" (above structure_height_m) or "down" (table level).
//   3. Per part, a search over translations within search_radius_m for the footprint that
//      holds the most up points and the fewest down points (points inside other parts'
//      footprints are not counted): every 4 search_step_m over the radius, then every
//      search_step_m within 4 steps of the best; the centroid of the best translations, then a
//      point-to-plane ICP in x, y and yaw of the part's sampled surface (walls and roof edges
//      fix x and y) on the scan points near it.
//   4. Verdict: fewer than min_points scanned points where the part stands: unobserved. Up
//      fraction of the footprint's points below missing_support at the best translation:
//      missing. Moved by the found translation when it (or the footprint corners' turn by the
//      found yaw) exceeds moved_threshold_m and 3 sigma of its estimate (the fit's covariance
//      combined with the spread of the footprint search's equally good translations). Else
//      present. Present, or moved by no more than placement_tolerance_m: in place, the count
//      by which a placement of the model is judged (a scan of a wide site is off by several
//      mm here and there: grid-12's showed half its buildings 5-10 mm from where the right
//      placement put them; another layout leaves its buildings missing or further off).
//   5. Up points that no part (at its found position) explains and that stand more than
//      structure_height_m above the model there, grouped by 1 cm cells: extra structures of at
//      least min_extra_points points.
// Cost: O(parts x translations x points near the part) for step 3.
#pragma once

#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/base/status.h"
#include "common/geometry/rigid3.h"
#include "common/scene/scene.h"

namespace sandtable::node {

struct ModelChangeOptions {
  double structure_height_m = 0.005;
  double cell_m = 0.0025;
  double sample_spacing_m = 0.003;
  double search_radius_m = 0.06;
  double search_step_m = 0.0025;
  double moved_threshold_m = 0.005;
  double placement_tolerance_m = 0.015;
  double missing_support = 0.3;
  int min_points = 4;
  double icp_gate_m = 0.004;
  int min_extra_points = 8;
  Status Check() const;
};

struct ModelPart {
  std::vector<int> triangles;
  Eigen::AlignedBox3d bounds_m;  // model frame
};

// Step 1: the model's buildings. Parts are ordered by the lowest triangle index they hold (the
// order the glTF lists them in).
std::vector<ModelPart> SegmentModelParts(const Scene& model, double structure_height_m);

enum class PartState { kPresent, kMoved, kMissing, kUnobserved };
std::string_view PartStateName(PartState state);  // "present", "moved", "missing", "unobserved"

struct PartChange {
  int part = 0;  // index into SegmentModelParts' result
  PartState state = PartState::kUnobserved;
  Eigen::Vector3d centre_in_model_m = Eigen::Vector3d::Zero();  // of its bounds
  Eigen::Vector3d size_m = Eigen::Vector3d::Zero();
  int points_on_footprint = 0;  // scan points where the model has it
  double support = 0.0;         // up fraction of those
  // Where the scan shows it relative to the model, model frame: translation in x, y (m) and
  // rotation about its centre (deg). Zero unless found (present or moved).
  Eigen::Vector2d moved_by_m = Eigen::Vector2d::Zero();
  double moved_yaw_deg = 0.0;
  double fit_rms_mm = 0.0;
  int fit_points = 0;
  // One-sigma uncertainty of moved_by_m (its length) and of the yaw.
  double moved_sigma_mm = 0.0;
  double yaw_sigma_deg = 0.0;
  // The larger of the translation and the footprint corners' turn by the yaw (m).
  double displacement_m = 0.0;
};

struct ExtraStructure {
  Eigen::Vector3d centre_in_model_m = Eigen::Vector3d::Zero();
  Eigen::Vector2d size_m = Eigen::Vector2d::Zero();  // extent in model x, y
  double height_m = 0.0;                             // highest point above the model there
  int points = 0;
};

struct ModelChangeReport {
  std::vector<PartChange> parts;
  std::vector<ExtraStructure> extras;
  int present = 0, moved = 0, missing = 0, unobserved = 0;
  int in_place = 0;     // present, or moved by no more than placement_tolerance_m
  double time_s = 0.0;  // thread CPU
};

Expected<ModelChangeReport> DetectModelChanges(const Scene& model,
                                               std::span<const Eigen::Vector3d> scan_in_table_m,
                                               const Rigid3d& table_from_model,
                                               const ModelChangeOptions& options = {});

}  // namespace sandtable::node
