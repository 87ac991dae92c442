// Session import and export: crafted files that are cut, out of range or inconsistent are
// refused naming the line and field, and import nothing; export replaces the previous file
// atomically and keeps it when the write fails.
#include "coordinator/annotations/session_file.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "tests/cluster/annotation_test_util.h"
#include "tests/testing/temp_dir_test.h"

namespace sandtable::coordinator {
namespace {

namespace fs = std::filesystem;
using cluster::testing::Begin;
using cluster::testing::End;
using cluster::testing::LinePoint;
using cluster::testing::Points;

class SessionFileTest : public test_support::TempDirTest {
 protected:
  SessionFileTest() : TempDirTest("session_test") {}

  // A valid session of 8 events: 2 strokes of begin, 2 points events, end.
  std::vector<wire::AnnotationEvent> Events() const {
    std::vector<wire::AnnotationEvent> events;
    for (int s = 1; s <= 2; ++s) {
      events.push_back(Begin(s));
      events.push_back(Points(s, 0, {LinePoint(0), LinePoint(1)}));
      events.push_back(Points(s, 2, {LinePoint(2)}));
      events.push_back(End(s, 3));
    }
    for (size_t i = 0; i < events.size(); ++i) events[i].set_event_sequence(i + 1);
    return events;
  }
  std::string Write(const std::string& name, const std::string& text) const {
    std::ofstream(Path(name), std::ios::binary | std::ios::trunc) << text;
    return Path(name);
  }
  // Imports `text` into a new store: must fail; returns the message; checks nothing imported.
  std::string Refused(const std::string& text) {
    const std::string file = Write("s.jsonl", text);
    Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(":memory:");
    EXPECT_TRUE(store.ok());
    Expected<size_t> imported = ImportSession(file, store->get());
    EXPECT_FALSE(imported.ok()) << "imported " << (imported.ok() ? *imported : 0);
    EXPECT_EQ((*store)->last_sequence(), 0u) << "a refused file imported events";
    return imported.ok() ? "" : imported.status().ToString();
  }
};

TEST_F(SessionFileTest, ValidFileImportsEveryEvent) {
  const std::string file = Write("ok.jsonl", SessionText(Events()));
  Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(":memory:");
  ASSERT_TRUE(store.ok());
  Expected<size_t> imported = ImportSession(file, store->get());
  ASSERT_TRUE(imported.ok()) << imported.status().ToString();
  EXPECT_EQ(*imported, 8u);
  EXPECT_EQ((*store)->state().NumPoints(), 6u);
}

TEST_F(SessionFileTest, FileCutAtALineBreakIsRefused) {
  const std::string text = SessionText(Events());
  // Cut after the 4th line (header + 3 events), at a line break.
  size_t cut = 0;
  for (int i = 0; i < 4; ++i) cut = text.find('\n', cut) + 1;
  const std::string refusal = Refused(text.substr(0, cut));
  EXPECT_NE(refusal.find("event_count 8 but the file holds 3 event lines"), std::string::npos)
      << refusal;
  EXPECT_NE(refusal.find("line 1"), std::string::npos) << refusal;
}

TEST_F(SessionFileTest, FileCutMidLineIsRefusedNamingTheLine) {
  const std::string text = SessionText(Events());
  const std::string refusal = Refused(text.substr(0, text.size() - 10));
  EXPECT_NE(refusal.find("line 9"), std::string::npos) << refusal;
}

TEST_F(SessionFileTest, OutOfRangeNumbersAreRefusedNamingTheField) {
  struct Case {
    std::string from, to, field;
  };
  const std::vector<Case> cases = {
      {"\"first_point_index\":2", "\"first_point_index\":4294967298", "first_point_index"},
      {"\"first_point_index\":2", "\"first_point_index\":-1", "first_point_index"},
      {"\"first_point_index\":2", "\"first_point_index\":2.5", "first_point_index"},
      {"\"stroke_id\":2", "\"stroke_id\":18446744073709551616", "line"},
      {"\"stroke_id\":2", "\"stroke_id\":-2", "stroke_id"},
      {"\"point_count\":3", "\"point_count\":4294967296", "point_count"},
      {"\"width_m\":0.004999999888241291", "\"width_m\":1e300", "width_m"},
      {"\"width_m\":0.004999999888241291", "\"width_m\":\"wide\"", "width_m"},
      {"\"event_sequence\":7", "\"event_sequence\":70", "event_sequence"},
      {"\"time_ns\":0", "\"time_ns\":9223372036854775808", "time_ns"},
      {"\"event_count\":8", "\"event_count\":4294967296", "event_count"},
      {"\"event_count\":8", "\"event_count\":-8", "event_count"},
      {"\"event_count\":8", "\"event_count\":7", "more event lines"},
      {"\"kind\":\"erase\"", "\"kind\":\"erase\"", ""},
  };
  const std::string text = SessionText(Events());
  for (const Case& c : cases) {
    if (c.field.empty()) continue;
    const size_t at = text.find(c.from);
    ASSERT_NE(at, std::string::npos) << c.from << " not in\n" << text;
    std::string changed = text;
    changed.replace(at, c.from.size(), c.to);
    const std::string refusal = Refused(changed);
    EXPECT_NE(refusal.find(c.field), std::string::npos) << c.to << ": " << refusal;
    EXPECT_NE(refusal.find("line "), std::string::npos) << c.to << ": " << refusal;
  }
}

TEST_F(SessionFileTest, EventThatDoesNotApplyImportsNothing) {
  std::vector<wire::AnnotationEvent> events = Events();
  events[6].mutable_stroke_points()->set_first_point_index(5);  // a gap in stroke 2
  const std::string refusal = Refused(SessionText(events));
  EXPECT_NE(refusal.find("line 8"), std::string::npos) << refusal;
  EXPECT_NE(refusal.find("first_point_index 5"), std::string::npos) << refusal;
}

TEST_F(SessionFileTest, NotAFileAndOversizedInputsAreRefused) {
  const std::string refusal = Refused("");
  EXPECT_NE(refusal.find("empty"), std::string::npos) << refusal;
  Expected<std::vector<wire::AnnotationEvent>> dir = ReadSessionFile(dir_.string());
  ASSERT_FALSE(dir.ok());
  Expected<std::vector<wire::AnnotationEvent>> zero = ReadSessionFile("/dev/zero");
  ASSERT_FALSE(zero.ok());
  EXPECT_NE(zero.status().message().find("/dev/zero"), std::string::npos);
}

TEST_F(SessionFileTest, HeaderOnlyAndBlankLinesInTheMiddle) {
  Expected<std::vector<wire::AnnotationEvent>> empty = ParseSession(
      "{\"format\":\"sandtable-annotation-session\",\"version\":1,\"event_count\":0}\n", "x");
  ASSERT_TRUE(empty.ok()) << empty.status().ToString();
  EXPECT_TRUE(empty->empty());
  std::string text = SessionText(Events());
  text.insert(text.find('\n') + 1, "\n");
  const std::string refusal = Refused(text);
  EXPECT_NE(refusal.find("line 2 is empty"), std::string::npos) << refusal;
}

TEST_F(SessionFileTest, ExportIsAtomicAndRoundTrips) {
  Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(":memory:");
  ASSERT_TRUE(store.ok());
  std::vector<wire::AnnotationEvent> events = Events();
  ASSERT_TRUE((*store)->Commit(&events).ok());
  const std::string file = Path("out.jsonl");
  ASSERT_TRUE(ExportSession(**store, file).ok());
  std::stringstream first;
  first << std::ifstream(file).rdbuf();
  Expected<std::vector<wire::AnnotationEvent>> back = ReadSessionFile(file);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->size(), 8u);
  // A target in a folder that does not exist fails and names it; a failed export (here: the
  // target is a folder, so the rename fails) leaves the previous file as it was.
  EXPECT_FALSE(ExportSession(**store, Path("missing/out.jsonl")).ok());
  fs::create_directories(Path("taken"));
  std::ofstream(Path("taken/keep"), std::ios::trunc) << "x";
  EXPECT_FALSE(ExportSession(**store, Path("taken")).ok());
  std::stringstream again;
  again << std::ifstream(file).rdbuf();
  EXPECT_EQ(again.str(), first.str());
}

}  // namespace
}  // namespace sandtable::coordinator
