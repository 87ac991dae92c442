#include "cluster/annotation_state.h"

#include <gtest/gtest.h>

#include <limits>

#include "tests/cluster/annotation_test_util.h"

namespace sandtable::cluster {
namespace {

using testing::Begin;
using testing::End;
using testing::LinePoint;
using testing::Points;
using testing::SpotErase;

// Applies with consecutive sequence numbers; fails the test on a rejected event.
class Applier {
 public:
  void Apply(wire::AnnotationEvent e) {
    e.set_event_sequence(++sequence_);
    Status s = state_.Check(e);
    ASSERT_TRUE(s.ok()) << s.ToString();
    state_.Apply(e);
  }
  AnnotationState state_;
  SequenceNumber sequence_ = 0;
};

std::vector<Eigen::Vector3f> Line(int first, int count) {
  std::vector<Eigen::Vector3f> out;
  for (int k = first; k < first + count; ++k) out.push_back(LinePoint(k));
  return out;
}

TEST(AnnotationStateTest, BuildsStrokesInOrder) {
  Applier a;
  a.Apply(Begin(1, 0.f, 1.f, 0.f, 0.004f));
  a.Apply(Points(1, 0, Line(0, 3)));
  a.Apply(Points(1, 3, Line(3, 2)));
  a.Apply(End(1, 5));
  ASSERT_EQ(a.state_.strokes().size(), 1u);
  const Stroke& s = a.state_.strokes().at(1);
  EXPECT_EQ(s.points_in_table_m.size(), 5u);
  EXPECT_TRUE(s.ended);
  EXPECT_EQ(s.points_in_table_m[4], LinePoint(4));
  EXPECT_FLOAT_EQ(s.color_rgb.y(), 1.f);
  EXPECT_EQ(a.state_.last_sequence(), 4u);
  const wire::Snapshot snap = a.state_.ToSnapshot();
  ASSERT_EQ(snap.strokes_size(), 1);
  EXPECT_EQ(snap.strokes(0).points_in_table_m_size(), 15);
  EXPECT_TRUE(snap.strokes(0).ended());
  EXPECT_EQ(snap.last_event_sequence(), 4u);
}

TEST(AnnotationStateTest, RejectsInvalidEventsWithReasons) {
  Applier a;
  a.Apply(Begin(1));
  AnnotationState& st = a.state_;
  EXPECT_FALSE(st.Check(Begin(1)).ok());                        // duplicate id
  EXPECT_FALSE(st.Check(Begin(0)).ok());                        // id 0
  EXPECT_FALSE(st.Check(Begin(kDerivedStrokeIdBit | 5)).ok());  // reserved id range
  EXPECT_FALSE(st.Check(Begin(2, 1.5f)).ok());                  // colour > 1
  EXPECT_FALSE(st.Check(Begin(2, 1.f, 0.f, 0.f, 0.f)).ok());    // width 0
  EXPECT_FALSE(st.Check(Begin(2, 1.f, 0.f, 0.f, 0.9f)).ok());   // width > max
  EXPECT_FALSE(st.Check(Points(9, 0, Line(0, 1))).ok());        // unknown stroke
  EXPECT_FALSE(st.Check(Points(1, 1, Line(0, 1))).ok());        // gap
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(st.Check(Points(1, 0, {Eigen::Vector3f(nan, 0, 0)})).ok());
  wire::AnnotationEvent ragged = Points(1, 0, Line(0, 1));
  ragged.mutable_stroke_points()->add_points_in_table_m(1.f);  // not xyz triples
  EXPECT_FALSE(st.Check(ragged).ok());
  EXPECT_FALSE(st.Check(wire::AnnotationEvent()).ok());  // no kind
  EXPECT_FALSE(st.Check(SpotErase(Eigen::Vector3d::Zero(), 0.f)).ok());
  a.Apply(End(1, 0));
  const Status after_end = st.Check(Points(1, 0, Line(0, 1)));
  EXPECT_FALSE(after_end.ok());
  EXPECT_NE(after_end.message().find("has ended"), std::string::npos) << after_end.message();
}

TEST(AnnotationStateTest, SpotEraseSplitsStrokesDeterministically) {
  Applier a;
  a.Apply(Begin(1));
  a.Apply(Points(1, 0, Line(0, 21)));  // x = 0 .. 0.20 m
  a.Apply(End(1, 21));
  a.Apply(Begin(2));
  a.Apply(Points(2, 0, {Eigen::Vector3f(0.5f, 0.5f, 0.f)}));  // far away: untouched, open
  // Disc of 0.025 m around x = 0.10 removes points 8..12 (x within 0.075 .. 0.125).
  a.Apply(SpotErase(Eigen::Vector3d(0.10, 0.2, 0.0), 0.025f));
  const SequenceNumber erase_sequence = a.sequence_;
  const auto& strokes = a.state_.strokes();
  ASSERT_EQ(strokes.size(), 3u);
  EXPECT_EQ(strokes.at(1).points_in_table_m.size(), 8u);  // points 0..7
  const StrokeId derived = kDerivedStrokeIdBit | (erase_sequence << 16) | 1;
  ASSERT_EQ(strokes.count(derived), 1u);
  EXPECT_EQ(strokes.at(derived).points_in_table_m.size(), 8u);  // points 13..20
  EXPECT_EQ(strokes.at(derived).points_in_table_m.front(), LinePoint(13));
  EXPECT_TRUE(strokes.at(derived).ended);
  EXPECT_FALSE(strokes.at(2).ended);
  // Erasing everything of a stroke removes it.
  a.Apply(SpotErase(Eigen::Vector3d(0.5, 0.5, 0.0), 0.01f));
  EXPECT_EQ(a.state_.strokes().count(2), 0u);
  a.Apply(wire::AnnotationEvent(Begin(3)));
  wire::AnnotationEvent clear;
  clear.mutable_clear();
  a.Apply(clear);
  EXPECT_TRUE(a.state_.strokes().empty());
}

}  // namespace
}  // namespace sandtable::cluster
