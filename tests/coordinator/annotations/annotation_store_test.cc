#include "coordinator/annotations/annotation_store.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "coordinator/annotations/session_file.h"
#include "tests/cluster/annotation_test_util.h"
#include "tests/testing/temp_dir_test.h"

namespace sandtable::coordinator {
namespace {

namespace fs = std::filesystem;
using cluster::testing::Begin;
using cluster::testing::End;
using cluster::testing::LinePoint;
using cluster::testing::Points;
using cluster::testing::SpotErase;

class AnnotationStoreTest : public test_support::TempDirTest {
 protected:
  AnnotationStoreTest() : TempDirTest("store_test") {}

  // Writes `strokes` strokes of `points` points each (one event per point) to a new store.
  std::unique_ptr<AnnotationStore> Fill(const std::string& path, int strokes, int points) {
    Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(path);
    EXPECT_TRUE(store.ok()) << store.status().ToString();
    for (int s = 1; s <= strokes; ++s) {
      std::vector<wire::AnnotationEvent> batch{Begin(s)};
      for (int k = 0; k < points; ++k) batch.push_back(Points(s, k, {LinePoint(k, 0.01f * s)}));
      batch.push_back(End(s, points));
      Expected<CommitReport> report = (*store)->Commit(&batch);
      EXPECT_TRUE(report.ok()) << report.status().ToString();
      EXPECT_EQ(report->num_committed, batch.size());
    }
    return std::move(*store);
  }
};

TEST_F(AnnotationStoreTest, CommittedEventsSurviveReopen) {
  const std::string path = Path("a.db");
  const wire::Snapshot before = Fill(path, 3, 10)->state().ToSnapshot();
  Expected<std::unique_ptr<AnnotationStore>> reopened = AnnotationStore::Open(path);
  ASSERT_TRUE(reopened.ok()) << reopened.status().ToString();
  EXPECT_EQ((*reopened)->events_loaded(), 3u * 12u);
  EXPECT_EQ((*reopened)->last_sequence(), 36u);
  EXPECT_EQ((*reopened)->state().ToSnapshot().SerializeAsString(), before.SerializeAsString());
  Expected<std::vector<wire::AnnotationEvent>> tail = (*reopened)->EventsAfter(30, 100);
  ASSERT_TRUE(tail.ok());
  ASSERT_EQ(tail->size(), 6u);
  EXPECT_EQ(tail->front().event_sequence(), 31u);
}

TEST_F(AnnotationStoreTest, RejectedEventsInABatchAreNotWrittenOthersAre) {
  Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(Path("b.db"));
  ASSERT_TRUE(store.ok());
  std::vector<wire::AnnotationEvent> batch{Begin(1), Points(7, 0, {LinePoint(0)}),
                                           Points(1, 0, {LinePoint(0)})};
  Expected<CommitReport> report = (*store)->Commit(&batch);
  ASSERT_TRUE(report.ok());
  EXPECT_TRUE(report->results[0].ok());
  EXPECT_FALSE(report->results[1].ok());
  EXPECT_TRUE(report->results[2].ok());
  EXPECT_EQ(batch[2].event_sequence(), 2u);  // sequences have no gaps
  EXPECT_EQ((*store)->last_sequence(), 2u);
}

TEST_F(AnnotationStoreTest, FileThatIsNotADatabaseGivesAClearError) {
  const std::string path = Path("garbage.db");
  std::mt19937 rng(7);
  std::ofstream(path, std::ios::binary)
      << std::string(8192, 'x') << static_cast<char>(rng() & 0xff);
  Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(path);
  ASSERT_FALSE(store.ok());
  EXPECT_NE(store.status().message().find("not a database"), std::string::npos)
      << store.status().ToString();
  EXPECT_NE(store.status().message().find(path), std::string::npos);
}

TEST_F(AnnotationStoreTest, DamagedPagesGiveAClearError) {
  const std::string path = Path("damaged.db");
  Fill(path, 40, 50);  // ~2 000 events: many pages
  {
    Expected<std::unique_ptr<AnnotationStore>> check = AnnotationStore::Open(path);
    ASSERT_TRUE(check.ok());  // checkpoints the WAL into the main file on close
  }
  const auto size = fs::file_size(path);
  ASSERT_GT(size, 8u * 4096u);
  std::mt19937 rng(11);
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  for (uint64_t page = 2; page * 4096 < size; page += 2) {  // every other page from page 3
    f.seekp(static_cast<std::streamoff>(page * 4096 + 100));
    for (int i = 0; i < 1000; ++i) f.put(static_cast<char>(rng() & 0xff));
  }
  f.close();
  Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(path);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kParseError) << store.status().ToString();
  EXPECT_NE(store.status().message().find("damaged"), std::string::npos)
      << store.status().ToString();
}

TEST_F(AnnotationStoreTest, TruncatedDatabaseGivesAnErrorNotACrash) {
  const std::string path = Path("truncated.db");
  Fill(path, 20, 50);
  { ASSERT_TRUE(AnnotationStore::Open(path).ok()); }
  fs::resize_file(path, fs::file_size(path) / 2);
  Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(path);
  ASSERT_FALSE(store.ok());
  EXPECT_NE(store.status().message().find(path), std::string::npos);
}

TEST_F(AnnotationStoreTest, SessionExportImportRoundTrip) {
  const std::string path = Path("c.db");
  std::unique_ptr<AnnotationStore> store = Fill(path, 4, 20);
  std::vector<wire::AnnotationEvent> erase{SpotErase(Eigen::Vector3d(0.1, 0.2, 0.02), 0.02f)};
  ASSERT_TRUE(store->Commit(&erase).ok());
  const std::string session = Path("session.jsonl");
  Expected<size_t> exported = ExportSession(*store, session);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_EQ(*exported, store->last_sequence());
  Expected<std::unique_ptr<AnnotationStore>> copy = AnnotationStore::Open(Path("copy.db"));
  ASSERT_TRUE(copy.ok());
  Expected<size_t> imported = ImportSession(session, copy->get());
  ASSERT_TRUE(imported.ok()) << imported.status().ToString();
  EXPECT_EQ(*imported, *exported);
  EXPECT_EQ((*copy)->state().ToSnapshot().SerializeAsString(),
            store->state().ToSnapshot().SerializeAsString());
  // Importing into a store that holds events is refused.
  EXPECT_FALSE(ImportSession(session, copy->get()).ok());
}

TEST_F(AnnotationStoreTest, SessionImportNamesTheBadLineAndImportsNothing) {
  const std::string session = Path("bad.jsonl");
  std::ofstream(session) << "{\"format\":\"sandtable-annotation-session\",\"version\":1,"
                            "\"event_count\":2}\n"
                         << AnnotationEventToJsonLine(Begin(1)) << "\n"
                         << "{\"kind\":\"stroke_points\",\"stroke_id\":1,"
                            "\"first_point_index\":0,\"points_in_table_m\":[[1,2]]}\n";
  Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(Path("d.db"));
  ASSERT_TRUE(store.ok());
  Expected<size_t> imported = ImportSession(session, store->get());
  ASSERT_FALSE(imported.ok());
  EXPECT_NE(imported.status().message().find("line 3"), std::string::npos)
      << imported.status().ToString();
  EXPECT_EQ((*store)->last_sequence(), 0u);
}

}  // namespace
}  // namespace sandtable::coordinator
