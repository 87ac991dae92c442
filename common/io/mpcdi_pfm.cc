// The PFM codec of MPCDI warp grids (mpcdi.h: netpbm PFM, RGB float32, bottom row first).
#include "common/io/mpcdi.h"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <optional>

namespace sandtable {

namespace {

void AppendLittleEndianFloat(float value, std::string* out) {
  uint32_t bits = 0;
  std::memcpy(&bits, &value, sizeof(bits));
  for (int k = 0; k < 4; ++k) out->push_back(static_cast<char>((bits >> (8 * k)) & 0xffu));
}

float ReadFloat(const unsigned char* p, bool little_endian) {
  uint32_t bits = 0;
  for (int k = 0; k < 4; ++k) {
    bits |= uint32_t{p[little_endian ? k : 3 - k]} << (8 * k);
  }
  float value = 0.0f;
  std::memcpy(&value, &bits, sizeof(value));
  return value;
}

// The next whitespace-delimited token of a PFM header from `*at` (skipping leading whitespace),
// at most 32 characters; empty when none.
std::string_view PfmToken(std::string_view bytes, size_t* at) {
  auto space = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; };
  while (*at < bytes.size() && space(bytes[*at])) ++*at;
  const size_t begin = *at;
  while (*at < bytes.size() && !space(bytes[*at]) && *at - begin <= 32) ++*at;
  return bytes.substr(begin, *at - begin);
}

std::optional<int64_t> PositiveInteger(std::string_view token) {
  if (token.empty() || token.size() > 9) return std::nullopt;
  int64_t value = 0;
  for (char c : token) {
    if (c < '0' || c > '9') return std::nullopt;
    value = value * 10 + (c - '0');
  }
  if (value <= 0) return std::nullopt;
  return value;
}

}  // namespace

std::string EncodeMpcdiPfm(const MpcdiWarp& warp) {
  std::string out = "PF\n" + std::to_string(warp.samples_x) + " " + std::to_string(warp.samples_y) +
                    "\n-1.000000\n";
  out.reserve(out.size() + warp.samples.size() * 12);
  // netpbm PFM: the bottom row first.
  for (int j = warp.samples_y - 1; j >= 0; --j) {
    for (int i = 0; i < warp.samples_x; ++i) {
      const Eigen::Vector3f& s = warp.samples[static_cast<size_t>(j) * warp.samples_x + i];
      for (int k = 0; k < 3; ++k) AppendLittleEndianFloat(s[k], &out);
    }
  }
  return out;
}

Expected<MpcdiWarp> DecodeMpcdiPfm(std::string_view bytes, std::string_view source) {
  const std::string what(source);
  if (bytes.size() >= 2 && bytes.substr(0, 2) == "Pf") {
    return ParseError(what +
                      ": greyscale PFM (\"Pf\"); an MPCDI warp is RGB (\"PF\", MPCDI 3.6.1)");
  }
  if (bytes.size() < 3 || bytes.substr(0, 2) != "PF" ||
      std::string_view(" \t\r\n").find(bytes[2]) == std::string_view::npos) {
    return ParseError(what + ": not a PFM file (header must start with \"PF\" and a newline)");
  }
  size_t at = 2;
  const std::string_view width_token = PfmToken(bytes, &at);
  const std::string_view height_token = PfmToken(bytes, &at);
  const std::string_view scale_token = PfmToken(bytes, &at);
  const std::optional<int64_t> width = PositiveInteger(width_token);
  const std::optional<int64_t> height = PositiveInteger(height_token);
  if (!width || !height) {
    return ParseError(what + ": PFM header width/height \"" + std::string(width_token) + " " +
                      std::string(height_token) + "\" are not positive integers");
  }
  double scale = 0.0;
  {
    const std::string scale_text(scale_token);
    char* end = nullptr;
    scale = scale_text.empty() ? 0.0 : std::strtod(scale_text.c_str(), &end);
    if (scale_text.empty() || end != scale_text.c_str() + scale_text.size() ||
        !std::isfinite(scale) || scale == 0.0) {
      return ParseError(what + ": PFM header scale \"" + scale_text +
                        "\" is not a finite non-zero number");
    }
  }
  // Exactly one whitespace character ends the header.
  if (at >= bytes.size() || std::string_view(" \t\r\n").find(bytes[at]) == std::string_view::npos) {
    return ParseError(what + ": PFM header does not end with a whitespace character");
  }
  ++at;
  if (*width > kMaxMpcdiWarpSide || *height > kMaxMpcdiWarpSide ||
      *width * *height > kMaxMpcdiWarpSamples) {
    return InvalidArgumentError(what + ": PFM of " + std::to_string(*width) + "x" +
                                std::to_string(*height) +
                                " samples is over kMaxMpcdiWarpSide or kMaxMpcdiWarpSamples");
  }
  const uint64_t expected = static_cast<uint64_t>(*width * *height) * 12;
  if (bytes.size() - at != expected) {
    return ParseError(what + ": PFM data is " + std::to_string(bytes.size() - at) +
                      " bytes, its header's " + std::to_string(*width) + "x" +
                      std::to_string(*height) + " RGB float32 needs " + std::to_string(expected));
  }
  MpcdiWarp warp;
  warp.samples_x = static_cast<int>(*width);
  warp.samples_y = static_cast<int>(*height);
  warp.samples.resize(static_cast<size_t>(*width * *height));
  const bool little_endian = scale < 0.0;
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data() + at);
  for (int j = warp.samples_y - 1; j >= 0; --j) {  // bottom row first
    for (int i = 0; i < warp.samples_x; ++i, p += 12) {
      warp.samples[static_cast<size_t>(j) * warp.samples_x + i] =
          Eigen::Vector3f(ReadFloat(p, little_endian), ReadFloat(p + 4, little_endian),
                          ReadFloat(p + 8, little_endian));
    }
  }
  return warp;
}

}  // namespace sandtable
