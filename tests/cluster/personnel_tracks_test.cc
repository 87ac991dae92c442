#include "cluster/personnel_tracks.h"

#include <cmath>
#include <string>

#include <gtest/gtest.h>

namespace sandtable::cluster {
namespace {

constexpr double kTolerance_m = 1e-12;

constexpr const char* kTwoTracks =
    "# two walkers\n"
    "track_id,t_s,x_m,y_m,z_m\n"
    "1,0,0,0,0\n"
    "2,1,1,1,0\n"
    "1,2,0.3,0.4,0\n"  // 0.5 m in 2 s
    "2,3,1,2,0\n"
    "1,4,0.3,0.4,1.2\n"
    "\n";

PersonnelTracks Parse(const char* text) {
  Expected<PersonnelTracks> t = PersonnelTracks::Parse(text, "tracks.csv");
  EXPECT_TRUE(t.ok()) << t.status().ToString();
  return t.ok() ? *t : PersonnelTracks{};
}

TEST(TimelinePersonnelTracksTest, ParsesInterleavedTracks) {
  const PersonnelTracks t = Parse(kTwoTracks);
  ASSERT_EQ(t.tracks().size(), 2u);
  EXPECT_EQ(t.tracks().at(1).size(), 3u);
  EXPECT_EQ(t.tracks().at(2).size(), 2u);
  EXPECT_EQ(t.sample_count(), 5u);
  EXPECT_DOUBLE_EQ(t.duration_s(), 4.0);
}

TEST(TimelinePersonnelTracksTest, InterpolatesLinearlyAndClampsOutsideTheSpan) {
  const PersonnelTracks t = Parse(kTwoTracks);
  Expected<TrackPositionAt> p = t.PositionAt(1, 1.0);
  ASSERT_TRUE(p.ok());
  EXPECT_TRUE(p->active);
  EXPECT_NEAR((p->position_in_table_m - Eigen::Vector3d(0.15, 0.2, 0.0)).norm(), 0.0, kTolerance_m);
  p = t.PositionAt(1, 3.5);
  EXPECT_NEAR((p->position_in_table_m - Eigen::Vector3d(0.3, 0.4, 0.9)).norm(), 0.0, kTolerance_m);
  // Track 2 starts at 1 s: before it, its first sample, inactive.
  p = t.PositionAt(2, 0.5);
  EXPECT_FALSE(p->active);
  EXPECT_NEAR((p->position_in_table_m - Eigen::Vector3d(1, 1, 0)).norm(), 0.0, kTolerance_m);
  p = t.PositionAt(2, 3.9);
  EXPECT_FALSE(p->active);
  EXPECT_NEAR((p->position_in_table_m - Eigen::Vector3d(1, 2, 0)).norm(), 0.0, kTolerance_m);
  // Exactly on a sample.
  p = t.PositionAt(1, 2.0);
  EXPECT_NEAR((p->position_in_table_m - Eigen::Vector3d(0.3, 0.4, 0)).norm(), 0.0, kTolerance_m);
  EXPECT_EQ(t.PositionAt(7, 1.0).status().code(), StatusCode::kNotFound);
  EXPECT_FALSE(t.PositionAt(1, std::nan("")).ok());
}

TEST(TimelinePersonnelTracksTest, DistanceAlongTheTrack) {
  const PersonnelTracks t = Parse(kTwoTracks);
  // Whole track: 0.5 m + 1.2 m.
  EXPECT_NEAR(*t.DistanceAlong_m(1, 0.0, 4.0), 1.7, kTolerance_m);
  // Partial segments on both ends: 1 s -> 3 s = 0.25 + 0.6.
  EXPECT_NEAR(*t.DistanceAlong_m(1, 1.0, 3.0), 0.85, kTolerance_m);
  // Inside one segment.
  EXPECT_NEAR(*t.DistanceAlong_m(1, 0.5, 1.5), 0.25, kTolerance_m);
  // Outside the span is clamped; zero-length interval.
  EXPECT_NEAR(*t.DistanceAlong_m(1, -10.0, 100.0), 1.7, kTolerance_m);
  EXPECT_NEAR(*t.DistanceAlong_m(2, 2.0, 2.0), 0.0, kTolerance_m);
  EXPECT_FALSE(t.DistanceAlong_m(1, 3.0, 1.0).ok());
  EXPECT_FALSE(t.DistanceAlong_m(9, 0.0, 1.0).ok());
}

// Each malformed file: the error names the line number and the field.
struct Malformed {
  const char* text;
  const char* expected;  // substring of the message
};

TEST(TimelinePersonnelTracksTest, MalformedFilesNameLineAndField) {
  const Malformed cases[] = {
      {"", "empty"},
      {"id,t,x,y,z\n1,0,0,0,0\n", "tracks.csv:1: header"},
      {"track_id,t_s,x_m,y_m,z_m\n1,0,0,0\n", "tracks.csv:2: expected 5 fields"},
      {"track_id,t_s,x_m,y_m,z_m\n1,0,0,0,0,9\n", "tracks.csv:2: expected 5 fields"},
      {"track_id,t_s,x_m,y_m,z_m\n1,0,0,0,0\nx,1,0,0,0\n", "tracks.csv:3: field track_id"},
      {"track_id,t_s,x_m,y_m,z_m\n-1,1,0,0,0\n", "tracks.csv:2: field track_id"},
      {"track_id,t_s,x_m,y_m,z_m\n1,abc,0,0,0\n", "tracks.csv:2: field t_s: 'abc'"},
      {"track_id,t_s,x_m,y_m,z_m\n1,0,0,nan,0\n", "tracks.csv:2: field y_m"},
      {"track_id,t_s,x_m,y_m,z_m\n1,0,0,0,\n", "tracks.csv:2: field z_m"},
      {"track_id,t_s,x_m,y_m,z_m\n1,0,0.5m,0,0\n", "tracks.csv:2: field x_m"},
      {"track_id,t_s,x_m,y_m,z_m\n1,-2,0,0,0\n", "tracks.csv:2: field t_s: -2 is negative"},
      {"track_id,t_s,x_m,y_m,z_m\n1,2,0,0,0\n2,1,0,0,0\n1,2,0,0,0\n",
       "tracks.csv:4: field t_s: 2 of track 1 is not after"},
  };
  for (const Malformed& c : cases) {
    Expected<PersonnelTracks> t = PersonnelTracks::Parse(c.text, "tracks.csv");
    ASSERT_FALSE(t.ok()) << c.text;
    EXPECT_EQ(t.status().code(), StatusCode::kParseError) << c.text;
    EXPECT_NE(t.status().message().find(c.expected), std::string::npos)
        << t.status().message() << " / expected " << c.expected;
  }
}

TEST(TimelinePersonnelTracksTest, MissingFileIsNotFoundNamingIt) {
  const Status missing = PersonnelTracks::Load("/nonexistent/tracks.csv").status();
  EXPECT_EQ(missing.code(), StatusCode::kNotFound);  // common/base/file_io.h
  EXPECT_NE(missing.message().find("/nonexistent/tracks.csv"), std::string::npos);
}

// The report: a 2.6-million-track file made every timeline clock exceed the codec limit. One
// track past kMaxTimelineTracks is refused, naming the limit and the line.
TEST(TimelinePersonnelTracksTest, TracksPastTheLimitAreRefusedNamingIt) {
  std::string text = "track_id,t_s,x_m,y_m,z_m\n";
  for (size_t track = 0; track <= kMaxTimelineTracks; ++track) {
    text += std::to_string(track) + ",0,0,0,0\n";
  }
  Expected<PersonnelTracks> t = PersonnelTracks::Parse(text, "many.csv");
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.status().message().find("kMaxTimelineTracks"), std::string::npos)
      << t.status().ToString();
  EXPECT_NE(t.status().message().find("many.csv:" + std::to_string(kMaxTimelineTracks + 2)),
            std::string::npos)
      << t.status().ToString();
  // Exactly at the limit is fine.
  text = "track_id,t_s,x_m,y_m,z_m\n";
  for (size_t track = 0; track < kMaxTimelineTracks; ++track) {
    text += std::to_string(track) + ",0,0,0,0\n";
  }
  EXPECT_TRUE(PersonnelTracks::Parse(text, "max.csv").ok());
  EXPECT_FALSE(PersonnelTracks::Load("/dev/zero").ok());  // not a regular file
}

}  // namespace
}  // namespace sandtable::cluster
