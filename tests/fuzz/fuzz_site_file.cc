// libFuzzer target over the site file parser (sim/site/site_json.h), from bytes: JSON text ->
// SiteFromJson (format, table, units, projector/camera models and poses, Site::Check with its
// limits). Invariant: a site that parses re-serialises (SiteToJson) and parses again. Seeds in
// tests/fuzz/site_file_corpus/ (presets and near-misses); see deploy/fuzz.sh.
#include <cstdint>
#include <string_view>

#include "common/base/check.h"
#include "common/io/json_reader.h"
#include "sim/site/site_json.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace sandtable;
  // Site files are small; past 1 MiB the parser's cost, not its logic, is exercised.
  if (size > (1u << 20)) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  Expected<nlohmann::json> json = io::ParseJsonText(text, "fuzz.site.json");
  if (!json.ok()) return 0;
  Expected<sim::Site> site = sim::SiteFromJson(*json);
  if (!site.ok()) return 0;
  Expected<sim::Site> again = sim::SiteFromJson(sim::SiteToJson(*site));
  ST_CHECK(again.ok()) << "a parsed site must re-parse: " << again.status().ToString();
  ST_CHECK(again->units.size() == site->units.size());
  return 0;
}
