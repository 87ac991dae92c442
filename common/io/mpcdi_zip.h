// ZIP archives in memory, as MPCDI's container (VESA MPCDI 1a section 3.3: a ZIP archive, every
// file at its root). minizip (Debian libminizip-dev) over a byte buffer: no temporary files, so
// that the archive can be written with WriteFileAtomically and read through ReadInputFile.
//
// Writing: deflate, no timestamps (DOS date 1980-01-01), no comments, entries in the given
// order; the same entries give the same bytes. Reading treats the archive as untrusted: the
// entry count, each entry's declared uncompressed size and the total are bounded BEFORE
// anything is inflated, an entry that inflates to other than its declared size or fails its
// CRC is refused, and so are encrypted entries, methods other than stored and deflate,
// duplicate names and names with a folder part.
// Codes: PARSE_ERROR for a damaged archive (truncated, bad CRC, bad method), INVALID_ARGUMENT
// over a limit or for a bad name; every message starts with `source` and names the entry.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "common/base/status.h"

namespace sandtable::io {

struct ZipEntry {
  std::string name;   // a plain file name: no '/', '\\' or NUL, not "." or ".."
  std::string bytes;  // uncompressed
};

struct ZipReadLimits {
  int max_entries = 4096;
  uint64_t max_entry_bytes = uint64_t{256} << 20;  // uncompressed, per entry
  uint64_t max_total_bytes = uint64_t{1} << 30;    // uncompressed, all entries
};

// True when `bytes` start as a ZIP archive does (a local file header "PK\3\4" or, for an empty
// archive, the end-of-central-directory record "PK\5\6").
bool LooksLikeZip(std::string_view bytes);

// INVALID_ARGUMENT for an empty, duplicate or non-plain name; INTERNAL if minizip fails.
Expected<std::string> EncodeZipArchive(const std::vector<ZipEntry>& entries);

// Every entry of the archive, in the archive's order.
Expected<std::vector<ZipEntry>> DecodeZipArchive(std::string_view bytes, std::string_view source,
                                                 const ZipReadLimits& limits = {});

}  // namespace sandtable::io
