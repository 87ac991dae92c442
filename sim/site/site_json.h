// Reads and writes site files (JSON, documented in docs/site-file.md).
//
// Failure: malformed JSON or a field of the wrong type gives PARSE_ERROR naming the file, the
// unit and the field ("site.json: units[1].projector.fx_px: expected a number"); the parsed site
// is then validated with Site::Check() (INVALID_ARGUMENT naming unit and field). Unknown keys
// are rejected so typos do not silently fall back to defaults.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "common/base/status.h"
#include "sim/site/site.h"

namespace sandtable::sim {

Expected<Site> SiteFromJson(const nlohmann::json& json);
nlohmann::json SiteToJson(const Site& site);

Expected<Site> LoadSiteFile(const std::string& path);
Status WriteSiteFile(const Site& site, const std::string& path);

// Pieces shared with the factory calibration files.
nlohmann::json CameraModelToJson(const CameraModel& model);
nlohmann::json RigidToJson(const Rigid3d& target_from_source);

}  // namespace sandtable::sim
