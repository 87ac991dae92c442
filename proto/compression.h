// zlib compression of message bodies (proto/codec.h decides when it pays).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

#include "common/base/status.h"

namespace sandtable::proto {

// zlib stream (RFC 1950) of `raw`; level 1 (fast) to 9 (small). Never fails for sane sizes.
std::string ZlibCompress(std::string_view raw, int level = 1);

// Inflates `compressed`, which must decode to exactly `expected_size` bytes; PARSE_ERROR if
// the stream is corrupt, truncated or of another size. `expected_size` comes from the
// (untrusted) header: the caller bounds it before calling, so a small message can never make
// us allocate more than the limit (no decompression bombs).
Expected<std::string> ZlibDecompress(std::string_view compressed, size_t expected_size);

}  // namespace sandtable::proto
