// report.html (sim/lab/lab_html.h): the report's markdown rendered with its tables, local PNG
// pictures inlined as data URIs that decode to the same bytes, anything else left as it is.
#include "sim/lab/lab_html.h"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "common/io/image_file.h"

namespace sandtable::sim {
namespace {

TEST(LabHtmlTest, Base64MatchesRfc4648) {
  // RFC 4648, section 10.
  EXPECT_EQ(Base64(""), "");
  EXPECT_EQ(Base64("f"), "Zg==");
  EXPECT_EQ(Base64("fo"), "Zm8=");
  EXPECT_EQ(Base64("foo"), "Zm9v");
  EXPECT_EQ(Base64("foob"), "Zm9vYg==");
  EXPECT_EQ(Base64("fooba"), "Zm9vYmE=");
  EXPECT_EQ(Base64("foobar"), "Zm9vYmFy");
  EXPECT_EQ(Base64(std::string("\xff\xfe\x00", 3)), "//4A");
}

TEST(LabHtmlTest, RendersTablesAndInlinesLocalPictures) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "lab_html_test";
  std::filesystem::create_directories(dir);
  const cv::Mat picture(4, 6, CV_8UC1, cv::Scalar(128));
  ASSERT_TRUE(io::WritePngFile((dir / "a.png").string(), picture).ok());
  std::ifstream in(dir / "a.png", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string markdown =
      "# Report <x>\n\n| figure | value |\n| --- | --- |\n| rms | 0.1 mm |\n\n"
      "![local](a.png)\n![missing](b.png)\n![remote](https://example.org/c.png)\n";
  Expected<std::string> html = MarkdownToHtmlPage(markdown, dir.string(), "T & <t>");
  ASSERT_TRUE(html.ok()) << html.status().ToString();
  EXPECT_NE(html->find("<title>T &amp; &lt;t&gt;</title>"), std::string::npos);
  EXPECT_NE(html->find("<table>"), std::string::npos);
  EXPECT_NE(html->find("<td>0.1 mm</td>"), std::string::npos);
  EXPECT_NE(html->find("<img src=\"data:image/png;base64," + Base64(bytes) + "\""),
            std::string::npos);
  EXPECT_NE(html->find("<img src=\"b.png\""), std::string::npos);
  EXPECT_NE(html->find("<img src=\"https://example.org/c.png\""), std::string::npos);
  EXPECT_EQ(html->find("<img src=\"a.png\""), std::string::npos);
  EXPECT_EQ(html->rfind("</html>\n"), html->size() - 8);
}

}  // namespace
}  // namespace sandtable::sim
