#include "node/devices/replay_camera_input.h"

#include <algorithm>
#include <cctype>
#include <set>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/base/log.h"
#include "common/io/image_file.h"

namespace sandtable::node {
namespace {

namespace fs = std::filesystem;

bool IsImageFile(const fs::path& path) {
  static const std::set<std::string> kExtensions = {".png",  ".jpg", ".jpeg", ".tif",
                                                    ".tiff", ".bmp", ".pgm",  ".ppm"};
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return kExtensions.count(extension) > 0;
}

bool IsDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

}  // namespace

bool NaturalLess(const std::string& a, const std::string& b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (IsDigit(a[i]) && IsDigit(b[j])) {
      size_t ie = i, je = j;
      while (ie < a.size() && IsDigit(a[ie])) ++ie;
      while (je < b.size() && IsDigit(b[je])) ++je;
      // Compare the numbers without leading zeros: first by length, then digit by digit.
      size_t is = i, js = j;
      while (is + 1 < ie && a[is] == '0') ++is;
      while (js + 1 < je && b[js] == '0') ++js;
      if (ie - is != je - js) return ie - is < je - js;
      const int order = a.compare(is, ie - is, b, js, je - js);
      if (order != 0) return order < 0;
      if (ie - i != je - j) return ie - i < je - j;  // "01" before "001": fewer zeros first
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

Expected<std::unique_ptr<ReplayCameraInput>> ReplayCameraInput::Open(const std::string& directory) {
  const std::string who = "replay " + directory;
  std::error_code error;
  if (!fs::is_directory(directory, error)) {
    return NotFoundError(who + ": no such directory (a folder of recorded captures)");
  }
  std::unique_ptr<ReplayCameraInput> camera(new ReplayCameraInput());
  camera->directory_ = directory;
  for (fs::directory_iterator it(directory, error), end; !error && it != end; it.increment(error)) {
    if (it->is_regular_file(error) && IsImageFile(it->path())) {
      if (camera->files_.size() >= kMaxReplayFrames) {
        return InvalidArgumentError(who + ": more than kMaxReplayFrames = " +
                                    std::to_string(kMaxReplayFrames) + " images in the folder");
      }
      camera->files_.push_back(it->path());
    }
  }
  if (error) return IoError(who + ": cannot list the folder: " + error.message());
  if (camera->files_.empty()) {
    return NotFoundError(who + ": no images (.png .jpg .tif .bmp .pgm .ppm) in the folder");
  }
  std::sort(camera->files_.begin(), camera->files_.end(), [](const fs::path& a, const fs::path& b) {
    return NaturalLess(a.filename().string(), b.filename().string());
  });
  Expected<cv::Mat> first = camera->Load(camera->files_.front());
  if (!first.ok()) return first.status();
  camera->size_px_ = first->size();
  camera->bit_depth_ = first->depth() == CV_16U ? 16 : 8;
  ST_LOG(kInfo) << who << ": " << camera->files_.size() << " frames, " << camera->size_px_.width
                << "x" << camera->size_px_.height << " " << camera->bit_depth_ << " bit";
  return camera;
}

Expected<cv::Mat> ReplayCameraInput::Load(const fs::path& file) const {
  // Regular files only, at most kMaxImageFileBytes, the header's size checked before decoding.
  Expected<cv::Mat> read = io::ReadImageFile(file.string(), cv::IMREAD_UNCHANGED);
  if (!read.ok()) return read.status().WithContext("replay");
  const cv::Mat raw = std::move(*read);
  if (raw.depth() != CV_8U && raw.depth() != CV_16U) {
    return InvalidArgumentError("replay " + file.string() + ": not an 8- or 16-bit image");
  }
  cv::Mat gray;
  switch (raw.channels()) {
    case 1:
      gray = raw;
      break;
    case 3:
      cv::cvtColor(raw, gray, cv::COLOR_BGR2GRAY);
      break;
    case 4:
      cv::cvtColor(raw, gray, cv::COLOR_BGRA2GRAY);
      break;
    default:
      return InvalidArgumentError("replay " + file.string() + ": " +
                                  std::to_string(raw.channels()) + " channels");
  }
  return gray;
}

Expected<CapturedFrame> ReplayCameraInput::Capture(Seconds /*exposure: recorded*/) {
  if (next_ >= files_.size()) {
    return OutOfRangeError(description() + ": end of recording (all " +
                           std::to_string(files_.size()) + " frames were captured)");
  }
  // A frame that fails is lost like a dropped frame: the next call gets the next file, so the
  // index of every frame returned still names its file.
  const fs::path& file = files_[next_++];
  Expected<cv::Mat> image = Load(file);
  if (!image.ok()) return image.status();
  const int depth = image->depth() == CV_16U ? 16 : 8;
  if (image->size() != size_px_ || depth != bit_depth_) {
    return InvalidArgumentError("replay " + file.string() + ": " + std::to_string(image->cols) +
                                "x" + std::to_string(image->rows) + " " + std::to_string(depth) +
                                " bit, the recording is " + std::to_string(size_px_.width) + "x" +
                                std::to_string(size_px_.height) + " " + std::to_string(bit_depth_) +
                                " bit");
  }
  CapturedFrame frame;
  frame.capture_time = DeviceClock::now();
  frame.image = std::move(*image);
  frame.index = next_;
  ST_LOG(kDebug) << description() << ": frame " << frame.index << " " << file.filename().string();
  return frame;
}

}  // namespace sandtable::node
