// MPCDI reader and writer: a synthetic site written and read back, the orientation convention,
// the two real files of ../shared/data/mpcdi (docs: ../shared/data/README.md section 4) read by
// the same reader, and hostile inputs (each a clear Status naming the file and the element).
#include "common/io/mpcdi.h"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>

#include <unistd.h>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "common/io/mpcdi_zip.h"

namespace sandtable {
namespace {

constexpr char kMomentFactory[] = "../shared/data/mpcdi/momentfactory/Cube-mapping.mpcdi.xml";
constexpr char kSgctCorrection[] = "../shared/data/mpcdi/sgct/correction_mesh.mpcdi";
constexpr char kSgctZero[] = "../shared/data/mpcdi/sgct/zero_distortion_mesh.mpcdi";

// Numbers are written with the shortest text that reads back to the same double.
constexpr double kRoundTripTolerance_deg = 0.0;
constexpr double kRoundTripTolerance_m = 0.0;
// Rotations composed from yaw/pitch/roll and decomposed again (a few ulps per product).
constexpr double kRotationTolerance = 1e-12;
// Values read off the real files, as printed there (6 decimals).
constexpr double kFileValueTolerance_deg = 1e-9;
// The Moment Factory file writes yaw -90.000008 for a quarter turn: 1.4e-7 rad off.
constexpr double kDirectionTolerance = 1e-6;
constexpr unsigned kSeed = 20261202;

bool SameFloat(float a, float b) { return (std::isnan(a) && std::isnan(b)) || a == b; }

MpcdiRegion ExampleRegion(const std::string& id, int width_px, int height_px, float offset) {
  MpcdiRegion region;
  region.id = id;
  region.x_resolution_px = width_px;
  region.y_resolution_px = height_px;
  region.x = 0.0;
  region.y = 0.0;
  region.x_size = 1.0;
  region.y_size = 1.0;
  MpcdiFrustum frustum;
  frustum.yaw_deg = 12.345678901234567;
  frustum.pitch_deg = -71.1;
  frustum.roll_deg = 0.1;
  frustum.right_angle_deg = 21.3;
  frustum.left_angle_deg = -19.87654321;
  frustum.up_angle_deg = 14.2;
  frustum.down_angle_deg = -9.25;
  region.frustum = frustum;
  MpcdiCoordinateFrame frame;
  frame.position = Eigen::Vector3d(0.4, -0.7, 1.5 + offset);
  region.coordinate_frame = frame;
  MpcdiWarp warp;
  warp.samples_x = 5;
  warp.samples_y = 4;
  for (int j = 0; j < warp.samples_y; ++j) {
    for (int i = 0; i < warp.samples_x; ++i) {
      warp.samples.emplace_back(0.1f * i + offset, -0.3f * j, 1e-3f * (i + j));
    }
  }
  const float nan = std::numeric_limits<float>::quiet_NaN();
  warp.samples[7] = Eigen::Vector3f(nan, nan, nan);  // a sample that lights nothing
  region.warp = warp;
  MpcdiBlendMap alpha;
  alpha.width_px = 7;
  alpha.height_px = 3;
  for (int k = 0; k < 21; ++k) alpha.values.push_back(static_cast<uint8_t>(12 * k + 3));
  region.alpha = alpha;
  return region;
}

MpcdiSite ExampleSite() {
  MpcdiSite site;
  site.date = "2026-12-02 10:11:12";
  site.buffer_id = "sandtable";
  site.buffer_x_resolution_px = 1280;
  site.buffer_y_resolution_px = 800;
  site.regions.push_back(ExampleRegion("unit-1", 1280, 800, 0.0f));
  site.regions.push_back(ExampleRegion("unit-2", 1280, 800, 0.5f));
  MpcdiBlendMap beta;
  beta.width_px = 2;
  beta.height_px = 2;
  beta.values = {0, 1, 2, 250};
  site.regions[1].beta = beta;
  return site;
}

class MpcdiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ =
        std::filesystem::temp_directory_path() / ("sandtable_mpcdi_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  std::string WriteBytes(const std::string& name, const std::string& bytes) const {
    std::ofstream(Path(name), std::ios::binary) << bytes;
    return Path(name);
  }
  static std::string ReadBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
  // Our archive of ExampleSite with entry `name` replaced by `bytes`.
  std::string ArchiveWith(const std::string& name, const std::string& bytes) const {
    Expected<std::string> archive = EncodeMpcdiArchive(ExampleSite());
    EXPECT_TRUE(archive.ok());
    Expected<std::vector<io::ZipEntry>> entries = io::DecodeZipArchive(*archive, "example");
    EXPECT_TRUE(entries.ok());
    bool replaced = false;
    for (io::ZipEntry& entry : *entries) {
      if (entry.name == name) {
        entry.bytes = bytes;
        replaced = true;
      }
    }
    EXPECT_TRUE(replaced) << name;
    return *io::EncodeZipArchive(*entries);
  }
  std::string ExampleXml() const {
    const Expected<std::string> archive = EncodeMpcdiArchive(ExampleSite());
    const Expected<std::vector<io::ZipEntry>> entries = io::DecodeZipArchive(*archive, "example");
    for (const io::ZipEntry& entry : *entries) {
      if (entry.name == kMpcdiXmlEntry) return entry.bytes;
    }
    ADD_FAILURE() << "no mpcdi.xml";
    return "";
  }

  std::filesystem::path dir_;
};

TEST_F(MpcdiTest, RoundTripOfASyntheticSite) {
  const MpcdiSite site = ExampleSite();
  const std::string path = Path("site.mpcdi");
  const Status written = WriteMpcdi(path, site);
  ASSERT_TRUE(written.ok()) << written.ToString();
  const Expected<MpcdiSite> read = ReadMpcdi(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();

  EXPECT_EQ(read->profile, "sl");
  EXPECT_EQ(read->level, 1);
  EXPECT_EQ(read->version, "1.0");
  EXPECT_EQ(read->date, site.date);
  EXPECT_EQ(read->buffer_id, "sandtable");
  EXPECT_EQ(read->buffer_x_resolution_px, 1280);
  EXPECT_EQ(read->buffer_y_resolution_px, 800);
  ASSERT_EQ(read->regions.size(), site.regions.size());
  for (size_t r = 0; r < site.regions.size(); ++r) {
    const MpcdiRegion& a = site.regions[r];
    const MpcdiRegion& b = read->regions[r];
    SCOPED_TRACE(a.id);
    EXPECT_EQ(b.id, a.id);
    EXPECT_EQ(b.x_resolution_px, a.x_resolution_px);
    EXPECT_EQ(b.y_resolution_px, a.y_resolution_px);
    EXPECT_EQ(b.x_size, a.x_size);
    ASSERT_TRUE(b.frustum && b.coordinate_frame && b.warp && b.alpha);
    EXPECT_NEAR(b.frustum->yaw_deg, a.frustum->yaw_deg, kRoundTripTolerance_deg);
    EXPECT_NEAR(b.frustum->pitch_deg, a.frustum->pitch_deg, kRoundTripTolerance_deg);
    EXPECT_NEAR(b.frustum->roll_deg, a.frustum->roll_deg, kRoundTripTolerance_deg);
    EXPECT_NEAR(b.frustum->left_angle_deg, a.frustum->left_angle_deg, kRoundTripTolerance_deg);
    EXPECT_NEAR(b.frustum->right_angle_deg, a.frustum->right_angle_deg, kRoundTripTolerance_deg);
    EXPECT_NEAR(b.frustum->up_angle_deg, a.frustum->up_angle_deg, kRoundTripTolerance_deg);
    EXPECT_NEAR(b.frustum->down_angle_deg, a.frustum->down_angle_deg, kRoundTripTolerance_deg);
    EXPECT_NEAR((b.coordinate_frame->position - a.coordinate_frame->position).norm(), 0.0,
                kRoundTripTolerance_m);
    EXPECT_EQ(b.coordinate_frame->yaw_axis, a.coordinate_frame->yaw_axis);
    EXPECT_EQ(b.coordinate_frame->pitch_axis, a.coordinate_frame->pitch_axis);
    EXPECT_EQ(b.coordinate_frame->roll_axis, a.coordinate_frame->roll_axis);
    // PFM contents: every float bit for bit, NaN where NaN was written.
    EXPECT_EQ(b.warp->samples_x, a.warp->samples_x);
    EXPECT_EQ(b.warp->samples_y, a.warp->samples_y);
    ASSERT_EQ(b.warp->samples.size(), a.warp->samples.size());
    for (size_t k = 0; k < a.warp->samples.size(); ++k) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_TRUE(SameFloat(b.warp->samples[k][c], a.warp->samples[k][c])) << k << " " << c;
      }
    }
    EXPECT_TRUE(std::isnan(b.warp->samples[7].x()));
    EXPECT_EQ(b.warp->interpolation, "linear");
    EXPECT_EQ(b.warp->geometric_unit, "m");
    EXPECT_EQ(b.warp->origin_of_3d_data, "unknown");
    // PNG contents.
    EXPECT_EQ(b.alpha->width_px, a.alpha->width_px);
    EXPECT_EQ(b.alpha->height_px, a.alpha->height_px);
    EXPECT_EQ(b.alpha->values, a.alpha->values);
    EXPECT_EQ(b.alpha->gamma_embedded, 1.0);
    EXPECT_EQ(b.beta.has_value(), a.beta.has_value());
    if (a.beta) {
      EXPECT_EQ(b.beta->values, a.beta->values);
    }
  }
}

TEST_F(MpcdiTest, ArchiveLayoutFollowsTheStandardAndTheReferenceLibrary) {
  Expected<std::string> archive = EncodeMpcdiArchive(ExampleSite());
  ASSERT_TRUE(archive.ok()) << archive.status().ToString();
  Expected<std::vector<io::ZipEntry>> entries = io::DecodeZipArchive(*archive, "site.mpcdi");
  ASSERT_TRUE(entries.ok()) << entries.status().ToString();
  std::vector<std::string> names;
  for (const io::ZipEntry& e : *entries) names.push_back(e.name);
  EXPECT_EQ(names, (std::vector<std::string>{"mpcdi.xml", "GeometryWarpFile-unit-1.pfm",
                                             "AlphaMap-unit-1.png", "GeometryWarpFile-unit-2.pfm",
                                             "AlphaMap-unit-2.png", "BetaMap-unit-2.png"}));
  const std::string& xml = (*entries)[0].bytes;
  for (const char* expected :
       {"<?xml version=\"1.0\" encoding=\"utf-8\"?>",
        "<MPCDI profile=\"sl\" level=\"1\" date=\"2026-12-02 10:11:12\" version=\"1.0\">",
        "<buffer id=\"sandtable\" Xresolution=\"1280\" Yresolution=\"800\">",
        "<region id=\"unit-1\" Xresolution=\"1280\" Yresolution=\"800\" x=\"0\" y=\"0\" "
        "xsize=\"1\" ysize=\"1\">",
        "<yaw>12.345678901234567</yaw>", "<leftAngle>-19.87654321</leftAngle>", "<yawz>-1</yawz>",
        "<rolly>1</rolly>", "<fileset region=\"unit-2\">",
        "<path>GeometryWarpFile-unit-2.pfm</path>", "<geometricUnit>m</geometricUnit>",
        "<interpolation>linear</interpolation>", "<originOf3DData>unknown</originOf3DData>",
        "<componentDepth>1</componentDepth>", "<bitDepth>8</bitDepth>",
        "<gammaEmbedded>1</gammaEmbedded>", "<path>BetaMap-unit-2.png</path>"}) {
    EXPECT_NE(xml.find(expected), std::string::npos) << expected << "\n" << xml;
  }
  // PFM: netpbm header, little-endian (scale -1), the BOTTOM row stored first.
  const std::string& pfm = (*entries)[1].bytes;
  const std::string header = "PF\n5 4\n-1.000000\n";
  ASSERT_EQ(pfm.substr(0, header.size()), header);
  ASSERT_EQ(pfm.size(), header.size() + 5 * 4 * 12);
  float first[3];
  std::memcpy(first, pfm.data() + header.size(), sizeof(first));
  const Eigen::Vector3f& bottom_left = ExampleSite().regions[0].warp->samples[3 * 5 + 0];
  EXPECT_EQ(first[0], bottom_left.x());
  EXPECT_EQ(first[1], bottom_left.y());
  EXPECT_EQ(first[2], bottom_left.z());
  // The same site gives the same bytes (no timestamps in the archive).
  EXPECT_EQ(*archive, *EncodeMpcdiArchive(ExampleSite()));
}

TEST(MpcdiOrientation, YawPitchRollRoundTripIncludingStraightDown) {
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> gauss;
  std::vector<Eigen::Matrix3d> rotations;
  for (int k = 0; k < 200; ++k) {
    rotations.push_back(
        Eigen::Quaterniond(gauss(rng), gauss(rng), gauss(rng), gauss(rng)).normalized().matrix());
  }
  // Straight down and straight up at the table: pitch -90 / +90 (gimbal lock).
  Eigen::Matrix3d down;
  down.col(0) = Eigen::Vector3d(0.6, 0.8, 0.0);   // right
  down.col(2) = Eigen::Vector3d(0.0, 0.0, -1.0);  // ahead
  down.col(1) = down.col(2).cross(down.col(0));   // down in the image
  rotations.push_back(down);
  rotations.push_back(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()) * down);
  const MpcdiCoordinateFrame frame;  // the table frame (mpcdi.h)
  for (const Eigen::Matrix3d& r : rotations) {
    MpcdiFrustum f;
    SetMpcdiOrientation(r, frame, &f);
    EXPECT_LE(std::abs(f.pitch_deg), 90.0);
    EXPECT_NEAR((MpcdiWorldFromViewer(f, frame) - r).norm(), 0.0, kRotationTolerance);
  }
  MpcdiFrustum f;
  SetMpcdiOrientation(down, frame, &f);
  EXPECT_NEAR(f.pitch_deg, -90.0, 1e-9);
  // Signs of MPCDI 1a Table 2-3 in the table frame: + yaw turns right (from +y toward +x),
  // + pitch looks up.
  MpcdiFrustum turned;
  turned.yaw_deg = 90.0;
  EXPECT_NEAR((MpcdiWorldFromViewer(turned, frame).col(2) - Eigen::Vector3d::UnitX()).norm(), 0.0,
              kRotationTolerance);
  MpcdiFrustum up;
  up.pitch_deg = 90.0;
  EXPECT_NEAR((MpcdiWorldFromViewer(up, frame).col(2) - Eigen::Vector3d::UnitZ()).norm(), 0.0,
              kRotationTolerance);
}

TEST(MpcdiRealFiles, MomentFactoryBareXml) {
  const Expected<MpcdiSite> site = ReadMpcdi(kMomentFactory);
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  EXPECT_EQ(site->profile, "3d");
  EXPECT_EQ(site->level, 2);  // geometry="2"
  EXPECT_EQ(site->version, "2.0");
  EXPECT_EQ(site->date, "2022-12-07 09-27-28");
  EXPECT_EQ(site->buffer_id, "0");
  EXPECT_EQ(site->buffer_x_resolution_px, 0);  // not given
  const std::vector<std::string> ids = {"Rear", "Front", "Left", "Right", "Top", "Bottom"};
  // Where each region looks under mpcdi.h's convention: at the cube's centre.
  const std::vector<Eigen::Vector3d> ahead = {{0, 0, -1}, {0, 0, 1},  {-1, 0, 0},
                                              {1, 0, 0},  {0, -1, 0}, {0, 1, 0}};
  ASSERT_EQ(site->regions.size(), ids.size());
  for (size_t r = 0; r < ids.size(); ++r) {
    const MpcdiRegion& region = site->regions[r];
    SCOPED_TRACE(region.id);
    EXPECT_EQ(region.id, ids[r]);
    EXPECT_EQ(region.x_resolution_px, 1920);
    EXPECT_EQ(region.y_resolution_px, 1080);
    EXPECT_EQ(region.x_size, 1.0);  // spelled xsize there
    ASSERT_TRUE(region.frustum && region.coordinate_frame);
    EXPECT_NEAR(region.frustum->right_angle_deg, 21.801409, kFileValueTolerance_deg);
    EXPECT_NEAR(region.frustum->left_angle_deg, -21.801409, kFileValueTolerance_deg);
    EXPECT_NEAR(region.frustum->up_angle_deg, 12.680382, kFileValueTolerance_deg);
    EXPECT_NEAR(region.frustum->down_angle_deg, -12.680382, kFileValueTolerance_deg);
    EXPECT_EQ(region.coordinate_frame->yaw_axis, Eigen::Vector3d(0, -1, 0));
    EXPECT_FALSE(region.warp.has_value());  // no <files>
    const Eigen::Vector3d forward =
        MpcdiWorldFromViewer(*region.frustum, region.coordinate_frame).col(2);
    EXPECT_NEAR((forward - ahead[r]).norm(), 0.0, kDirectionTolerance);
    EXPECT_LT(forward.dot(region.coordinate_frame->position), 0.0);  // toward the centre
  }
  EXPECT_NEAR(site->regions[2].frustum->yaw_deg, -90.000008, kFileValueTolerance_deg);
  EXPECT_NEAR(site->regions[4].frustum->pitch_deg, -90.0, kFileValueTolerance_deg);
  EXPECT_EQ(site->regions[4].coordinate_frame->position, Eigen::Vector3d(0, 3, 0));
}

TEST(MpcdiRealFiles, SgctArchives) {
  const Expected<MpcdiSite> site = ReadMpcdi(kSgctCorrection);
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  EXPECT_EQ(site->profile, "3d");
  EXPECT_EQ(site->level, 1);
  EXPECT_EQ(site->version, "2.0");
  EXPECT_EQ(site->buffer_id, "surface1");
  EXPECT_EQ(site->buffer_x_resolution_px, 512);
  EXPECT_EQ(site->buffer_y_resolution_px, 540);
  ASSERT_EQ(site->regions.size(), 1u);
  const MpcdiRegion& region = site->regions[0];
  EXPECT_EQ(region.id, "surface1_region");
  EXPECT_EQ(region.x_resolution_px, 512);
  EXPECT_EQ(region.y_resolution_px, 540);
  EXPECT_EQ(region.y_size, 1.0);  // spelled ySize there
  ASSERT_TRUE(region.frustum);
  EXPECT_FALSE(region.coordinate_frame);
  EXPECT_NEAR(region.frustum->yaw_deg, 326.675157, kFileValueTolerance_deg);
  EXPECT_NEAR(region.frustum->pitch_deg, 27.327616, kFileValueTolerance_deg);
  EXPECT_NEAR(region.frustum->roll_deg, -14.611227, kFileValueTolerance_deg);
  EXPECT_NEAR(region.frustum->right_angle_deg, 33.231552, kFileValueTolerance_deg);
  EXPECT_NEAR(region.frustum->down_angle_deg, -34.644394, kFileValueTolerance_deg);
  ASSERT_TRUE(region.warp);
  EXPECT_FALSE(region.alpha);  // <alphaMap />
  EXPECT_EQ(region.warp->samples_x, 32);
  EXPECT_EQ(region.warp->samples_y, 32);
  EXPECT_EQ(region.warp->interpolation, "linear");
  EXPECT_EQ(region.warp->geometric_unit, "");
  // 2D warp data (README section 4): offsets in channels 0 and 1, NaN in channel 2.
  float min0 = 1e9f, max0 = -1e9f;
  for (const Eigen::Vector3f& s : region.warp->samples) {
    EXPECT_TRUE(std::isnan(s.z()));
    min0 = std::min(min0, s.x());
    max0 = std::max(max0, s.x());
  }
  EXPECT_NEAR(min0, -0.2198f, 1e-4f);
  EXPECT_NEAR(max0, 0.1712f, 1e-4f);

  const Expected<MpcdiSite> zero = ReadMpcdi(kSgctZero);
  ASSERT_TRUE(zero.ok()) << zero.status().ToString();
  ASSERT_EQ(zero->regions.size(), 1u);
  EXPECT_EQ(zero->regions[0].frustum->yaw_deg, 326.675157167255);
  ASSERT_TRUE(zero->regions[0].warp);
  for (const Eigen::Vector3f& s : zero->regions[0].warp->samples) {
    EXPECT_EQ(s.x(), 0.0f);
    EXPECT_EQ(s.y(), 0.0f);
  }
}

// ------------------------------------------------------------------------------------------
// Hostile input: a Status with the right code, naming the file and the element, never a crash.

void ExpectError(const Expected<MpcdiSite>& site, StatusCode code,
                 std::initializer_list<const char*> named) {
  ASSERT_FALSE(site.ok());
  EXPECT_EQ(site.status().code(), code) << site.status().ToString();
  for (const char* n : named) {
    EXPECT_NE(site.status().message().find(n), std::string::npos)
        << "\"" << n << "\" not in: " << site.status().message();
  }
}

TEST_F(MpcdiTest, NonExistentPath) {
  const std::string path = Path("no-such-site.mpcdi");
  ExpectError(ReadMpcdi(path), StatusCode::kNotFound, {"no-such-site.mpcdi"});
}

TEST_F(MpcdiTest, TruncatedZip) {
  const std::string archive = *EncodeMpcdiArchive(ExampleSite());
  ExpectError(ReadMpcdi(WriteBytes("half.mpcdi", archive.substr(0, archive.size() / 2))),
              StatusCode::kParseError, {"half.mpcdi", "ZIP"});
  const std::string sgct = ReadBytes(kSgctCorrection);
  ASSERT_GT(sgct.size(), 100u);
  ExpectError(ReadMpcdi(WriteBytes("sgct-cut.mpcdi", sgct.substr(0, sgct.size() - 30))),
              StatusCode::kParseError, {"sgct-cut.mpcdi", "ZIP"});
  // The central directory intact but a compressed entry damaged: caught by inflate or the CRC.
  std::string damaged = archive;
  for (size_t k = 200; k < 260; ++k) damaged[k] = static_cast<char>(damaged[k] ^ 0x5a);
  ExpectError(ReadMpcdi(WriteBytes("damaged.mpcdi", damaged)), StatusCode::kParseError,
              {"damaged.mpcdi", "mpcdi.xml"});
}

TEST_F(MpcdiTest, XmlMissingARequiredAttribute) {
  std::string xml = ExampleXml();
  const std::string attribute = " xsize=\"1\"";
  const size_t at = xml.find(attribute);
  ASSERT_NE(at, std::string::npos);
  xml.erase(at, attribute.size());  // from region unit-1
  // In an archive and as a bare XML file: the same reader, the same message.
  ExpectError(ReadMpcdi(WriteBytes("no-xsize.mpcdi", ArchiveWith("mpcdi.xml", xml))),
              StatusCode::kParseError,
              {"no-xsize.mpcdi", "mpcdi.xml", "region[id=unit-1]", "attribute xsize missing"});
  ExpectError(ReadMpcdi(WriteBytes("no-xsize.mpcdi.xml", xml)), StatusCode::kParseError,
              {"no-xsize.mpcdi.xml", "region[id=unit-1]", "xsize", "line 5"});

  std::string no_yaw = ExampleXml();
  no_yaw.erase(no_yaw.find("<yaw>"), std::string("<yaw>12.345678901234567</yaw>").size());
  ExpectError(ReadMpcdi(WriteBytes("no-yaw.mpcdi", ArchiveWith("mpcdi.xml", no_yaw))),
              StatusCode::kParseError, {"region[id=unit-1]/frustum", "missing <yaw>"});

  std::string bad_number = ExampleXml();
  bad_number.replace(bad_number.find("<pitch>") + 7, 5, "abc");
  ExpectError(ReadMpcdi(WriteBytes("bad-pitch.mpcdi", ArchiveWith("mpcdi.xml", bad_number))),
              StatusCode::kParseError, {"<pitch>", "not a finite number"});

  ExpectError(ReadMpcdi(WriteBytes("garbage.xml", "<MPCDI profile=\"sl\"><display>")),
              StatusCode::kParseError, {"garbage.xml", "not well-formed XML"});
}

TEST_F(MpcdiTest, PfmWithAWrongHeaderOrSize) {
  const std::string pfm_name = "GeometryWarpFile-unit-2.pfm";
  ExpectError(ReadMpcdi(WriteBytes("p6.mpcdi", ArchiveWith(pfm_name, "P6\n5 4\n255\nxxxx"))),
              StatusCode::kParseError, {"p6.mpcdi", pfm_name.c_str(), "not a PFM"});
  ExpectError(ReadMpcdi(WriteBytes("grey.mpcdi", ArchiveWith(pfm_name, "Pf\n5 4\n-1.0\n"))),
              StatusCode::kParseError, {pfm_name.c_str(), "greyscale"});
  // The header says 5x4, the data holds 5x3.
  const std::string short_pfm = "PF\n5 4\n-1.000000\n" + std::string(5 * 3 * 12, '\0');
  ExpectError(ReadMpcdi(WriteBytes("short.mpcdi", ArchiveWith(pfm_name, short_pfm))),
              StatusCode::kParseError, {pfm_name.c_str(), "180 bytes", "needs 240"});
  // A header claiming 100000 x 100000 samples is refused before anything is allocated.
  ExpectError(ReadMpcdi(WriteBytes("huge.mpcdi", ArchiveWith(pfm_name, "PF\n100000 100000\n-1.0\n" +
                                                                           std::string(64, '\0')))),
              StatusCode::kInvalidArgument, {pfm_name.c_str(), "kMaxMpcdiWarpSide"});
  ExpectError(
      ReadMpcdi(WriteBytes("nan-scale.mpcdi", ArchiveWith(pfm_name, "PF\n5 4\nnan\n" + short_pfm))),
      StatusCode::kParseError, {pfm_name.c_str(), "scale"});
  // A PNG that is not one.
  ExpectError(ReadMpcdi(WriteBytes("png.mpcdi", ArchiveWith("AlphaMap-unit-1.png", "PNG?"))),
              StatusCode::kParseError, {"AlphaMap-unit-1.png", "not a PNG"});
}

TEST_F(MpcdiTest, DescriptorPointingOutsideOrNowhere) {
  std::string xml = ExampleXml();
  xml.replace(xml.find("GeometryWarpFile-unit-1.pfm"), 27, "../../etc/passwd");
  ExpectError(ReadMpcdi(WriteBytes("escape.mpcdi.xml", xml)), StatusCode::kInvalidArgument,
              {"escape.mpcdi.xml", "geometryWarpFile", "../../etc/passwd", "plain file name"});
  std::string missing = ExampleXml();
  missing.replace(missing.find("AlphaMap-unit-2.png"), 19, "AlphaMap-nowhere.png");
  ExpectError(ReadMpcdi(WriteBytes("missing.mpcdi", ArchiveWith("mpcdi.xml", missing))),
              StatusCode::kParseError, {"AlphaMap-nowhere.png", "names no entry"});
  // A bare XML file whose files are not beside it: NOT_FOUND naming the file.
  ExpectError(ReadMpcdi(WriteBytes("alone.mpcdi.xml", ExampleXml())), StatusCode::kNotFound,
              {"GeometryWarpFile-unit-1.pfm", "alone.mpcdi.xml"});
  std::string stranger = ExampleXml();
  stranger.replace(stranger.find("<fileset region=\"unit-2\">"), 25, "<fileset region=\"unit-9\">");
  ExpectError(ReadMpcdi(WriteBytes("stranger.mpcdi", ArchiveWith("mpcdi.xml", stranger))),
              StatusCode::kParseError, {"unit-9", "names no region"});
}

TEST_F(MpcdiTest, WriterRefusesWhatItCannotWriteCorrectly) {
  MpcdiSite site = ExampleSite();
  site.regions[0].id = "../unit";
  Status status = WriteMpcdi(Path("bad.mpcdi"), site);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("../unit"), std::string::npos) << status.ToString();
  site = ExampleSite();
  site.regions[1].coordinate_frame.reset();
  status = WriteMpcdi(Path("bad.mpcdi"), site);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("coordinate frame"), std::string::npos) << status.ToString();
  site = ExampleSite();
  site.regions[0].warp->samples.pop_back();
  EXPECT_EQ(WriteMpcdi(Path("bad.mpcdi"), site).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(std::filesystem::exists(Path("bad.mpcdi")));
}

}  // namespace
}  // namespace sandtable
