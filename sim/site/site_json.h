// Reads and writes site files (JSON, documented in docs/site-file.md): format "sandtable.site",
// version 1. Intrinsics and transforms use the common codec (common/io/json_codec.h). Files
// without "format"/"version" (written before they carried them) still load.
//
// Failure: malformed JSON or a field of the wrong type gives PARSE_ERROR naming the file, the
// unit and the field ("site.json: site.units[1].projector.fx_px must be a number"); values out
// of range give INVALID_ARGUMENT naming the field; the parsed site is then validated with
// Site::Check() (INVALID_ARGUMENT naming unit and field). Unknown keys are rejected so typos do
// not silently fall back to defaults.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "common/base/status.h"
#include "common/io/json_codec.h"
#include "sim/site/site.h"

namespace sandtable::sim {

inline constexpr char kSiteFormat[] = "sandtable.site";
inline constexpr int kSiteVersion = 1;

Expected<Site> SiteFromJson(const nlohmann::json& json);
nlohmann::json SiteToJson(const Site& site);

Expected<Site> LoadSiteFile(const std::string& path);
Status WriteSiteFile(const Site& site, const std::string& path);

// The codec's forms (kept under these names for sim code).
using io::CameraModelToJson;
using io::RigidToJson;

}  // namespace sandtable::sim
