#include "common/base/file_io.h"

#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "tests/testing/full_disk.h"

namespace sandtable {
namespace {

namespace fs = std::filesystem;

class FileIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("sandtable_file_io_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    fs::permissions(dir_, fs::perms::owner_all);
    fs::remove_all(dir_);
  }
  void Put(const fs::path& p, const std::string& text) { std::ofstream(p) << text; }
  std::string Get(const fs::path& p) {
    std::ifstream in(p);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
  fs::path dir_;
};

TEST_F(FileIoTest, ReadsARegularFile) {
  Put(dir_ / "a.json", "{\"x\": 1}");
  Expected<std::string> text = ReadInputFile(dir_ / "a.json", 100);
  ASSERT_TRUE(text.ok()) << text.status().ToString();
  EXPECT_EQ(*text, "{\"x\": 1}");
}

TEST_F(FileIoTest, RefusesMissingDirectoryFifoDeviceAndOversize) {
  Expected<std::string> missing = ReadInputFile(dir_ / "none", 100);
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("none"), std::string::npos);

  Expected<std::string> directory = ReadInputFile(dir_, 100);
  EXPECT_EQ(directory.status().code(), StatusCode::kIoError);
  EXPECT_NE(directory.status().message().find("directory"), std::string::npos);

  // A FIFO nobody writes to: refused at once, never opened for a blocking read.
  const fs::path fifo = dir_ / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  Expected<std::string> from_fifo = ReadInputFile(fifo, 100);
  EXPECT_EQ(from_fifo.status().code(), StatusCode::kIoError);
  EXPECT_NE(from_fifo.status().message().find("not a regular file"), std::string::npos);

  Expected<std::string> zero = ReadInputFile("/dev/zero", 100);
  EXPECT_EQ(zero.status().code(), StatusCode::kIoError);

  Put(dir_ / "big", std::string(101, 'x'));
  Expected<std::string> big = ReadInputFile(dir_ / "big", 100, "kMaxTest");
  EXPECT_EQ(big.status().code(), StatusCode::kIoError);
  EXPECT_NE(big.status().message().find("kMaxTest"), std::string::npos);
  EXPECT_TRUE(CheckInputFile(dir_ / "big", 101).ok());
  EXPECT_FALSE(CheckInputFile(dir_ / "big", 100).ok());
}

TEST_F(FileIoTest, WritesAtomicallyWithTheAskedMode) {
  const fs::path target = dir_ / "out.txt";
  ASSERT_TRUE(WriteFileAtomically(target, "first").ok());
  ASSERT_TRUE(WriteFileAtomically(target, "second", 0600).ok());
  EXPECT_EQ(Get(target), "second");
  struct stat st;
  ASSERT_EQ(::stat(target.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  // Nothing but the target is left in the folder.
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1);
}

TEST_F(FileIoTest, AFailedWriteKeepsThePreviousFile) {
  const fs::path target = dir_ / "export.json";
  ASSERT_TRUE(WriteFileAtomically(target, "old contents").ok());
  Status status;
  {
    test_support::FullDisk full_disk(8);  // writes past 8 bytes fail with EFBIG
    ASSERT_TRUE(full_disk.ok());
    status = WriteFileAtomically(target, std::string(4096, 'n'));
  }
  EXPECT_EQ(status.code(), StatusCode::kIoError);
  EXPECT_NE(status.message().find("unchanged"), std::string::npos) << status.ToString();
  EXPECT_EQ(Get(target), "old contents");
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1);

  // A folder that does not exist: an error, not an exception.
  EXPECT_EQ(WriteFileAtomically(dir_ / "no" / "such.txt", "x").code(), StatusCode::kIoError);
}

}  // namespace
}  // namespace sandtable
