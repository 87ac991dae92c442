// Hostile input and output files of common/io: a directory, a FIFO or /dev/zero where a file is
// expected, empty files, image headers that claim huge sizes (crafted here in bytes), and a full
// disk (RLIMIT_FSIZE with SIGXFSZ ignored) under the atomic writers.
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "common/io/image_file.h"
#include "common/io/json_reader.h"
#include "common/io/opencv_yaml.h"
#include "common/io/unit_calibration_file.h"
#include "common/structured_light/capture_io.h"
#include "tests/testing/full_disk.h"

namespace sandtable::io {
namespace {

namespace fs = std::filesystem;

// A refusal must come at once: nothing here may block on a FIFO or read /dev/zero to its end.
constexpr double kMaxRefusalTime_s = 5.0;

class InputFilesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("sandtable_io_inputs_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    fifo_ = (dir_ / "fifo.json").string();
    ASSERT_EQ(::mkfifo(fifo_.c_str(), 0600), 0);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  void Put(const std::string& name, const std::string& bytes) const {
    std::ofstream(Path(name), std::ios::binary) << bytes;
  }
  static std::string Get(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
  // Not-a-file paths: a folder, a FIFO (no writer: an open for reading would block), /dev/zero.
  std::vector<std::string> NotFiles() const { return {dir_.string(), fifo_, "/dev/zero"}; }

  fs::path dir_;
  std::string fifo_;
};

void ExpectRefusedQuickly(const std::function<Status()>& read, const std::string& path,
                          const std::string& why) {
  const auto start = std::chrono::steady_clock::now();
  const Status status = read();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_FALSE(status.ok()) << path;
  EXPECT_NE(status.message().find(path), std::string::npos) << status.ToString();
  EXPECT_NE(status.message().find(why), std::string::npos) << status.ToString();
  EXPECT_LT(seconds, kMaxRefusalTime_s) << path;
}

// The bytes of a PNG whose IHDR claims width x height (no image data follows).
std::string PngHeader(uint32_t width, uint32_t height) {
  std::string png = "\x89PNG\r\n\x1a\n";
  png += std::string("\0\0\0\x0d", 4) + "IHDR";
  for (uint32_t v : {width, height}) {
    for (int shift = 24; shift >= 0; shift -= 8) png += static_cast<char>((v >> shift) & 0xff);
  }
  png += std::string("\x08\x00\x00\x00\x00", 5);  // 8-bit gray, then a CRC that is wrong
  png += std::string(4, '\0');
  return png;
}

TEST_F(InputFilesTest, JsonReaderRefusesWhatIsNotAFile) {
  for (const std::string& path : NotFiles()) {
    ExpectRefusedQuickly([&] { return ReadJsonFile(path).status(); }, path, "regular file");
    EXPECT_EQ(ReadJsonFile(path).status().code(), StatusCode::kIoError);
  }
}

TEST_F(InputFilesTest, EmptyJsonIsNamedEmpty) {
  Put("empty.json", "");
  Put("blank.json", " \n\t\n");
  for (const char* name : {"empty.json", "blank.json"}) {
    const Status status = ReadJsonFile(Path(name)).status();
    EXPECT_EQ(status.code(), StatusCode::kParseError);
    EXPECT_NE(status.message().find("empty file"), std::string::npos) << status.ToString();
  }
}

TEST_F(InputFilesTest, UnitCalibrationAndYamlReadersRefuseWhatIsNotAFile) {
  for (const std::string& path : NotFiles()) {
    ExpectRefusedQuickly([&] { return LoadUnitCalibration(path).status(); }, path, "regular");
    ExpectRefusedQuickly([&] { return ReadOpenCvYaml(path).status(); }, path, "regular");
  }
}

TEST_F(InputFilesTest, YamlFromTextNeverThrows) {
  for (const std::string& text :
       {std::string(""), std::string("%YAML:1.0\n---\nformat: 3\n"), std::string("[[[[{{{:"),
        std::string("%YAML:1.0\n---\nformat: sandtable.opencv_calibration\nversion: x\n"),
        std::string("%YAML:1.0\nfx: !!opencv-matrix\n  rows: 99999\n  cols: 99999\n")}) {
    EXPECT_FALSE(ParseOpenCvYaml(text, "t.yaml").ok()) << text;
  }
}

TEST_F(InputFilesTest, FullDiskKeepsThePreviousJsonFile) {
  const std::string path = Path("site.json");
  ASSERT_TRUE(WriteJsonFile(nlohmann::json{{"old", true}}, path).ok());
  const std::string before = Get(path);
  Status status;
  {
    test_support::FullDisk full_disk(8);
    ASSERT_TRUE(full_disk.ok());
    status = WriteJsonFile(nlohmann::json{{"new", std::string(4096, 'x')}}, path);
  }
  EXPECT_EQ(status.code(), StatusCode::kIoError) << status.ToString();
  EXPECT_EQ(Get(path), before);
}

TEST_F(InputFilesTest, PngHeaderSizeIsCheckedBeforeDecoding) {
  EXPECT_EQ(ImageHeaderSize(PngHeader(40000, 40000)), cv::Size(40000, 40000));
  Put("huge.png", PngHeader(40000, 40000));
  Put("wide.png", PngHeader(9000, 8000));  // sides fine, area over kMaxImagePixels
  Put("zero.png", PngHeader(0, 10));
  Put("max.png", PngHeader(0xffffffffu, 0xffffffffu));
  const std::pair<const char*, const char*> cases[] = {{"huge.png", "kMaxImageSide_px"},
                                                       {"wide.png", "kMaxImagePixels"},
                                                       {"zero.png", "needs a size"},
                                                       {"max.png", "kMaxImageSide_px"}};
  for (const auto& [name, limit] : cases) {
    const Expected<cv::Mat> image = ReadImageFile(Path(name), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(image.ok()) << name;
    EXPECT_EQ(image.status().code(), StatusCode::kInvalidArgument) << image.status().ToString();
    EXPECT_NE(image.status().message().find(limit), std::string::npos) << image.status().ToString();
    EXPECT_NE(image.status().message().find(name), std::string::npos);
  }
}

TEST_F(InputFilesTest, BmpAndPnmHeadersAreCheckedToo) {
  std::string bmp = "BM" + std::string(16, '\0');
  for (int32_t v : {40000, -40000}) {
    for (int shift = 0; shift < 32; shift += 8) bmp += static_cast<char>((v >> shift) & 0xff);
  }
  EXPECT_EQ(ImageHeaderSize(bmp), cv::Size(40000, 40000));
  EXPECT_EQ(ImageHeaderSize("P5\n# comment\n 40000 30000\n255\n"), cv::Size(40000, 30000));
  Put("huge.pgm", "P5\n40000 40000\n255\n");
  const Expected<cv::Mat> image = ReadImageFile(Path("huge.pgm"), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(image.ok());
  EXPECT_NE(image.status().message().find("kMaxImageSide_px"), std::string::npos);
}

TEST_F(InputFilesTest, ImageReaderRefusesNotFilesEmptyAndGarbage) {
  for (const std::string& path : NotFiles()) {
    ExpectRefusedQuickly([&] { return ReadImageFile(path, cv::IMREAD_GRAYSCALE).status(); }, path,
                         "regular file");
  }
  Put("empty.png", "");
  Put("garbage.png", "not an image at all");
  EXPECT_NE(ReadImageFile(Path("empty.png"), 0).status().message().find("empty"),
            std::string::npos);
  EXPECT_NE(ReadImageFile(Path("garbage.png"), 0).status().message().find("decoded"),
            std::string::npos);
  EXPECT_EQ(ReadImageFile(Path("missing.png"), 0).status().code(), StatusCode::kNotFound);
}

TEST_F(InputFilesTest, PngRoundTripAndFullDiskKeepsThePreviousImage) {
  const cv::Mat image(24, 32, CV_8UC1, cv::Scalar(77));
  const std::string path = Path("out.png");
  ASSERT_TRUE(WritePngFile(path, image).ok());
  Expected<cv::Mat> back = ReadImageFile(path, cv::IMREAD_UNCHANGED);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(cv::countNonZero(*back != image), 0);
  const std::string before = Get(path);
  Status status;
  {
    test_support::FullDisk full_disk(16);
    ASSERT_TRUE(full_disk.ok());
    cv::Mat noise(256, 256, CV_8UC1);
    cv::randu(noise, 0, 255);
    status = WritePngFile(path, noise);
  }
  EXPECT_EQ(status.code(), StatusCode::kIoError) << status.ToString();
  EXPECT_EQ(Get(path), before);
}

TEST_F(InputFilesTest, CaptureSequenceRefusesHugeHeadersAndFifoFrames) {
  const CaptureSequenceNames names;
  Put("graycode_00.png", PngHeader(40000, 40000));
  Expected<std::vector<cv::Mat>> frames = LoadCaptureSequence(dir_.string(), 2, names);
  ASSERT_FALSE(frames.ok());
  EXPECT_NE(frames.status().message().find("kMaxImageSide_px"), std::string::npos)
      << frames.status().ToString();
  fs::remove(Path("graycode_00.png"));
  ASSERT_EQ(::mkfifo(Path("graycode_00.png").c_str(), 0600), 0);
  ExpectRefusedQuickly([&] { return LoadCaptureSequence(dir_.string(), 2, names).status(); },
                       Path("graycode_00.png"), "regular file");
  EXPECT_NE(LoadCaptureSequence(dir_.string(), kMaxCaptureFrames + 1, names)
                .status()
                .message()
                .find("kMaxCaptureFrames"),
            std::string::npos);
}

}  // namespace
}  // namespace sandtable::io
