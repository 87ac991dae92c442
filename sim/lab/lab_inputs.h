// The lab's inputs: the TRUE site and scene (from a preset or a file) and the files it hands to
// the world (site and scene) and to each node (its factory calibration, and in the labelled
// test mode its true pose).
//
// Layout under the output directory:
//   site.json                        the true site (sim/site/site_json.h), for the world only
//   scene.gltf                       the scene (presets are written; a FILE is used as given)
//   factory/unit-N.factory.json      what a real unit ships with (sandtable-world make-site's
//                                    factory files, from MakeFactoryCalibration and `seed`)
//   truth/unit-N.true_pose.json      LAB TEST MODE: {"format": "sandtable.true_pose",
//                                    "version": 1, "unit_id": N, "table_from_projector": RIGID,
//                                    "table_from_model": RIGID} from the site's truth; the model
//                                    stands where the glTF says, so table_from_model = identity
// Failure: INVALID_ARGUMENT naming the flag for an unknown preset or a file that does not load
// (the caller reports it as a usage error); IO_ERROR naming the path when a file cannot be
// written.
#pragma once

#include <cstdint>
#include <map>
#include <string>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "common/geometry/rigid3.h"
#include "common/scene/scene.h"
#include "sim/site/site.h"

namespace sandtable::sim {

struct LabInputs {
  Site site;
  std::string site_label;  // the preset name or the file given
  std::string scene_label;
  std::string site_path;  // the files the world loads
  std::string scene_path;
  std::map<NodeId, std::string> factory_paths;
  std::map<NodeId, std::string> true_pose_paths;
  // The model the nodes get (model.gltf, or the --model file) and where it truly stands:
  // x_in_model_file = model_from_table * x_in_table (the metric's true table_from_model is
  // its inverse).
  std::string model_path;
  Rigid3d model_from_table = Rigid3d::Identity();
};

// `site` / `scene`: a preset name (sandtable-3, grid-N, flat-4, random:SEED / sandtable, city,
// flat, random:SEED) or a file (site JSON / glTF). random:SEED draws a site (sim/site/
// random_site.h) or a scene (common/scene/random_scene.h) from its own seed, not `seed`. The scene
// presets use `seed`; so do the factory calibrations. `model`: "" writes model.gltf, the scene
// moved by a placement drawn from `seed` (up to kMaxModelOffset_m in x and y and kMaxModelYaw_deg
// about z); a file is handed over as given.
inline constexpr double kMaxModelOffset_m = 0.05;
inline constexpr double kMaxModelYaw_deg = 10.0;
// `resolution_scale` < 1: every projector and camera at that fraction of its resolution
// (ScaleSiteResolution), before site.json and the factory files are written. `device_timing`
// "ideal" or "real" (sim/site/device_timing.h) replaces every unit's timing; "" keeps the
// site's.
Expected<LabInputs> PrepareLabInputs(const std::string& site, const std::string& scene,
                                     uint64_t seed, const std::string& out_dir,
                                     const std::string& model = "", double resolution_scale = 1.0,
                                     const std::string& device_timing = "");

}  // namespace sandtable::sim
