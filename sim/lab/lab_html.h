// The lab's report as one self-contained HTML page: report.md rendered by cmark-gfm (GitHub
// tables), every image it links that lies in the report's folder inlined as a data URI, so the
// page opens in a browser on its own (mailed, archived, served).
#pragma once

#include <string>

#include "common/base/status.h"

namespace sandtable::sim {

// `markdown` as an HTML page titled `title`; an <img src="REL"> whose file is under `dir` (a PNG,
// at most 32 MiB) becomes a data URI; any other image link is left as it is. INTERNAL when the
// markdown cannot be rendered.
Expected<std::string> MarkdownToHtmlPage(const std::string& markdown, const std::string& dir,
                                         const std::string& title);

// Standard base64 (RFC 4648, with padding).
std::string Base64(const std::string& bytes);

}  // namespace sandtable::sim
