// The one way an image file (a capture frame, a projector frame, a recorded camera frame) is
// read and a PNG written.
//
// Reading: ReadImageFile reads the file through ReadInputFile (regular files only, at most
// kMaxImageFileBytes), then reads the image size from the header of a PNG, BMP or PGM/PPM file
// and refuses, naming the limit, a side over kMaxImageSide_px or an area over kMaxImagePixels
// BEFORE anything is decoded (a 100-byte PNG claiming 40000x40000 px never allocates). Other
// formats (JPEG, TIFF) are decoded by OpenCV under its own pixel limit, its exceptions caught,
// and the decoded size is then checked against the same limits. Codes: NOT_FOUND (missing),
// IO_ERROR (not a regular file, over a byte limit, not decodable), INVALID_ARGUMENT (over a
// size limit); every message names the path.
//
// Writing: WritePngFile encodes in memory (cv::imencode) and writes through WriteFileAtomically
// (the previous file stays on any failure).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "common/base/status.h"

namespace sandtable::io {

// Largest image file read: 256 MiB.
inline constexpr uint64_t kMaxImageFileBytes = uint64_t{256} << 20;
// Largest image side read, px.
inline constexpr int kMaxImageSide_px = 16384;
// Largest image area read, px (8192 x 8192; 256 MiB as 8-bit, 1 GiB as 32-bit float).
inline constexpr int64_t kMaxImagePixels = int64_t{8192} * 8192;

// Width and height of an image as its header states them (PNG IHDR, BMP, binary/ASCII PNM);
// nullopt for other formats or a header too short to say.
std::optional<cv::Size> ImageHeaderSize(std::string_view bytes);

// Checks a size against kMaxImageSide_px and kMaxImagePixels; `what` names the image.
Status CheckImageSize(int width_px, int height_px, const std::string& what);

// Reads and decodes the image at `path` with cv::imdecode `imread_flags` (see above).
Expected<cv::Mat> ReadImageFile(const std::string& path, int imread_flags);

// Encodes `image` as PNG and replaces the file at `path` with it, all or nothing.
Status WritePngFile(const std::string& path, const cv::Mat& image);

}  // namespace sandtable::io
