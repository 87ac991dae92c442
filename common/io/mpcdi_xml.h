// The mpcdi.xml descriptor (tinyxml2), for common/io/mpcdi*.cc only: names, conventions and the
// reader's rules are documented in mpcdi.h. The descriptor names the files of each region; the
// caller loads them (from the archive or beside a bare XML file).
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "common/base/status.h"
#include "common/io/mpcdi.h"

namespace sandtable::mpcdi_internal {

// Names of a region's files in our archives (the reference library's names).
std::string WarpFileName(const std::string& region_id);
std::string AlphaFileName(const std::string& region_id);
std::string BetaFileName(const std::string& region_id);

// The descriptor of a site that passed CheckForWriting, with `date` as the MPCDI date.
std::string EncodeMpcdiXml(const MpcdiSite& site, const std::string& date);

// A file the descriptor names, to be loaded into site.regions[region].
struct MpcdiFileRequest {
  enum class Kind { kWarp, kAlpha, kBeta };
  size_t region = 0;
  Kind kind = Kind::kWarp;
  std::string path;                        // a plain file name (checked)
  std::string element;                     // where it is named, for messages
  int component_depth = 0, bit_depth = 0;  // blend maps: as declared
};

struct ParsedMpcdiXml {
  MpcdiSite site;  // warp/alpha/beta present, without their data, where the descriptor has them
  std::vector<MpcdiFileRequest> files;
};

// `source` ("site.mpcdi: mpcdi.xml") prefixes every error.
Expected<ParsedMpcdiXml> ParseMpcdiXml(std::string_view xml, const std::string& source);

}  // namespace sandtable::mpcdi_internal
