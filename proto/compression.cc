#include "proto/compression.h"

#include <zlib.h>

#include <string>

namespace sandtable::proto {

std::string ZlibCompress(std::string_view raw, int level) {
  uLongf bound = compressBound(static_cast<uLong>(raw.size()));
  std::string out(bound, '\0');
  const int rc =
      compress2(reinterpret_cast<Bytef*>(out.data()), &bound,
                reinterpret_cast<const Bytef*>(raw.data()), static_cast<uLong>(raw.size()), level);
  ST_CHECK(rc == Z_OK) << "zlib compress2 failed (" << rc << ") on " << raw.size()
                       << " bytes; out of memory?";
  out.resize(bound);
  return out;
}

Expected<std::string> ZlibDecompress(std::string_view compressed, size_t expected_size) {
  std::string out(expected_size, '\0');
  uLongf out_size = static_cast<uLongf>(expected_size);
  uLong in_size = static_cast<uLong>(compressed.size());
  // uncompress2 reports how much input it consumed, so trailing garbage is detected too.
  const int rc = uncompress2(reinterpret_cast<Bytef*>(out.data()), &out_size,
                             reinterpret_cast<const Bytef*>(compressed.data()), &in_size);
  if (rc != Z_OK) {
    return ParseError("zlib body does not inflate to the announced " +
                      std::to_string(expected_size) + " bytes (zlib code " + std::to_string(rc) +
                      (rc == Z_BUF_ERROR ? ": larger than announced or truncated)" : ")"));
  }
  if (out_size != expected_size || in_size != compressed.size()) {
    return ParseError("zlib body inflates to " + std::to_string(out_size) + " bytes from " +
                      std::to_string(in_size) + " of " + std::to_string(compressed.size()) +
                      " input bytes; header announced " + std::to_string(expected_size));
  }
  return out;
}

}  // namespace sandtable::proto
