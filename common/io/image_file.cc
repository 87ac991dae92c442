#include "common/io/image_file.h"

#include <algorithm>
#include <climits>
#include <cstdlib>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "common/base/file_io.h"

namespace sandtable::io {

namespace {

int ClampToInt(uint64_t v) { return static_cast<int>(std::min<uint64_t>(v, INT_MAX)); }

uint32_t BigEndian32(const unsigned char* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | p[3];
}

uint32_t LittleEndian32(const unsigned char* p) {
  return (uint32_t{p[3]} << 24) | (uint32_t{p[2]} << 16) | (uint32_t{p[1]} << 8) | p[0];
}

// The next decimal number of a PNM header, skipping whitespace and '#' comments; nullopt past
// the end or at anything else.
std::optional<uint64_t> PnmNumber(std::string_view bytes, size_t* at) {
  while (*at < bytes.size()) {
    const char c = bytes[*at];
    if (c == '#') {
      while (*at < bytes.size() && bytes[*at] != '\n') ++*at;
    } else if (c == ' ' || c == '\t' || c == '\r' || c == '\n') {
      ++*at;
    } else {
      break;
    }
  }
  uint64_t value = 0;
  size_t digits = 0;
  while (*at < bytes.size() && bytes[*at] >= '0' && bytes[*at] <= '9') {
    if (value < (uint64_t{1} << 40)) value = value * 10 + static_cast<uint64_t>(bytes[*at] - '0');
    ++*at;
    ++digits;
  }
  if (digits == 0) return std::nullopt;
  return value;
}

}  // namespace

std::optional<cv::Size> ImageHeaderSize(std::string_view bytes) {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  static constexpr unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (bytes.size() >= 24 && std::equal(kPng, kPng + 8, p) && bytes.substr(12, 4) == "IHDR") {
    return cv::Size(ClampToInt(BigEndian32(p + 16)), ClampToInt(BigEndian32(p + 20)));
  }
  if (bytes.size() >= 26 && p[0] == 'B' && p[1] == 'M') {
    const auto width = static_cast<int32_t>(LittleEndian32(p + 18));
    const auto height = static_cast<int32_t>(LittleEndian32(p + 22));
    return cv::Size(ClampToInt(static_cast<uint64_t>(std::llabs(width))),
                    ClampToInt(static_cast<uint64_t>(std::llabs(height))));
  }
  if (bytes.size() >= 3 && p[0] == 'P' && p[1] >= '1' && p[1] <= '6') {
    size_t at = 2;
    const std::optional<uint64_t> width = PnmNumber(bytes, &at);
    const std::optional<uint64_t> height = width ? PnmNumber(bytes, &at) : std::nullopt;
    if (width && height) return cv::Size(ClampToInt(*width), ClampToInt(*height));
  }
  return std::nullopt;
}

Status CheckImageSize(int width_px, int height_px, const std::string& what) {
  const std::string size = std::to_string(width_px) + "x" + std::to_string(height_px) + " px";
  if (width_px <= 0 || height_px <= 0) {
    return InvalidArgumentError(what + ": " + size + ", an image needs a size");
  }
  if (width_px > kMaxImageSide_px || height_px > kMaxImageSide_px) {
    return InvalidArgumentError(what + ": " + size + ", a side over kMaxImageSide_px = " +
                                std::to_string(kMaxImageSide_px));
  }
  if (int64_t{width_px} * height_px > kMaxImagePixels) {
    return InvalidArgumentError(what + ": " + size +
                                ", more than kMaxImagePixels = " + std::to_string(kMaxImagePixels));
  }
  return OkStatus();
}

Expected<cv::Mat> ReadImageFile(const std::string& path, int imread_flags) {
  Expected<std::string> bytes = ReadInputFile(path, kMaxImageFileBytes, "kMaxImageFileBytes");
  if (!bytes.ok()) return bytes.status();
  if (bytes->empty()) return IoError(path + ": empty file, an image is expected");
  if (const std::optional<cv::Size> size = ImageHeaderSize(*bytes)) {
    ST_RETURN_IF_ERROR(CheckImageSize(size->width, size->height, path));
  }
  cv::Mat image;
  try {
    const cv::Mat raw(1, static_cast<int>(bytes->size()), CV_8U, bytes->data());
    image = cv::imdecode(raw, imread_flags);
  } catch (const cv::Exception& e) {
    return IoError(path + ": cannot be decoded as an image (OpenCV: " + e.what() + ")");
  }
  if (image.empty()) return IoError(path + ": cannot be decoded as an image");
  ST_RETURN_IF_ERROR(CheckImageSize(image.cols, image.rows, path));
  return image;
}

Status WritePngFile(const std::string& path, const cv::Mat& image) {
  if (image.empty()) return InvalidArgumentError(path + ": no image to write");
  std::vector<unsigned char> png;
  try {
    if (!cv::imencode(".png", image, png)) return IoError(path + ": PNG encoding failed");
  } catch (const cv::Exception& e) {
    return IoError(path + ": PNG encoding failed (OpenCV: " + e.what() + ")");
  }
  return WriteFileAtomically(
      path, std::string_view(reinterpret_cast<const char*>(png.data()), png.size()));
}

}  // namespace sandtable::io
