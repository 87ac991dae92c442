// AnnotationStore integrity at open: copies of a real database damaged the ways a disk, an
// operator or an editor damages them (rows changed with sqlite3 behind the store's back, rows
// deleted, a -wal file deleted or cut, the sequence record deleted or damaged, an older copy
// put back) are each refused with a message naming the database, the event and what to do; a
// second store on the same file is refused while the first holds it. The SIGKILL cases with a
// real coordinator are in annotation_crash_test.cc.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <filesystem>
#include <fstream>

#include "coordinator/annotations/annotation_store.h"
#include "coordinator/annotations/event_checksum.h"
#include "coordinator/annotations/sequence_record.h"
#include "tests/cluster/annotation_test_util.h"
#include "tests/testing/temp_dir_test.h"

namespace sandtable::coordinator {
namespace {

namespace fs = std::filesystem;
using cluster::testing::Begin;
using cluster::testing::End;
using cluster::testing::LinePoint;
using cluster::testing::Points;

constexpr int kStrokes = 5;
constexpr int kPointsPerStroke = 20;
constexpr uint64_t kEvents = kStrokes * (kPointsPerStroke + 2);

class StoreIntegrityTest : public test_support::TempDirTest {
 protected:
  StoreIntegrityTest() : TempDirTest("integrity_test") {}
  void SetUp() override {
    TempDirTest::SetUp();
    db_ = Path("a.db");
    std::unique_ptr<AnnotationStore> store = Open();
    ASSERT_TRUE(store);
    for (int s = 1; s <= kStrokes; ++s) {
      std::vector<wire::AnnotationEvent> batch{Begin(s)};
      for (int k = 0; k < kPointsPerStroke; ++k) {
        batch.push_back(Points(s, k, {LinePoint(k, 0.01f * s)}));
      }
      batch.push_back(End(s, kPointsPerStroke));
      ASSERT_TRUE(store->Commit(&batch).ok());
    }
    ASSERT_EQ(store->last_sequence(), kEvents);
  }

  std::unique_ptr<AnnotationStore> Open(const AnnotationStoreOptions& options = {}) {
    Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(db_, options);
    EXPECT_TRUE(store.ok()) << store.status().ToString();
    return store.ok() ? std::move(*store) : nullptr;
  }
  // The error of opening the database, which must fail.
  std::string Refusal(const AnnotationStoreOptions& options = {}) {
    Expected<std::unique_ptr<AnnotationStore>> store = AnnotationStore::Open(db_, options);
    EXPECT_FALSE(store.ok()) << "a damaged database was opened";
    if (store.ok()) return "";
    EXPECT_NE(store.status().message().find(db_), std::string::npos) << store.status().ToString();
    return store.status().ToString();
  }
  // Runs SQL on the database directly (as an operator with the sqlite3 tool would).
  void Sql(const std::string& sql) {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(db_.c_str(), &db), SQLITE_OK);
    char* error = nullptr;
    const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error);
    EXPECT_EQ(rc, SQLITE_OK) << (error ? error : "") << " in " << sql;
    sqlite3_free(error);
    sqlite3_close(db);
  }

  std::string db_;
};

// 1.5 the point coordinates of event 30, re-encoded in the body blob of its row: float bits of
// one coordinate changed in place (the blob's last 4 bytes are the last float).
TEST_F(StoreIntegrityTest, ChangedPointCoordinateIsDetectedAndNamed) {
  Sql("UPDATE events SET body = substr(body, 1, length(body) - 4) || x'0000c03f' "
      "WHERE sequence = 30");
  const std::string refusal = Refusal();
  EXPECT_NE(refusal.find("event 30"), std::string::npos) << refusal;
  EXPECT_NE(refusal.find("checksum mismatch"), std::string::npos) << refusal;
  EXPECT_NE(refusal.find("restore"), std::string::npos) << refusal;
}

TEST_F(StoreIntegrityTest, ChangedTimestampIsDetected) {
  Sql("UPDATE events SET time_ns = time_ns + 1 WHERE sequence = 7");
  const std::string refusal = Refusal();
  EXPECT_NE(refusal.find("event 7"), std::string::npos) << refusal;
  EXPECT_NE(refusal.find("checksum mismatch"), std::string::npos) << refusal;
}

TEST_F(StoreIntegrityTest, ChangedKindSequenceAndFlippedBodyByteAreDetected) {
  for (const std::string& change :
       {std::string("UPDATE events SET kind = 'erase' WHERE sequence = 3"),
        std::string("UPDATE events SET body = x'00' || substr(body, 2) WHERE sequence = 12"),
        std::string("UPDATE events SET sequence = 1000 WHERE sequence = 110")}) {
    SetUp();
    Sql(change);
    const std::string refusal = Refusal();
    // A moved sequence shows first as a gap; the others as checksum mismatches.
    EXPECT_TRUE(refusal.find("checksum mismatch") != std::string::npos ||
                refusal.find("are missing") != std::string::npos)
        << change << ": " << refusal;
  }
}

TEST_F(StoreIntegrityTest, ChangedRowWithARecomputedChecksumButDisagreeingBodyIsDetected) {
  // A forger who recomputes the checksum of a changed time_ns column still leaves the body's
  // own time_ns disagreeing with the row.
  Sql("SELECT 1");
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(db_.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* select = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT time_ns, kind, body FROM events WHERE sequence = 9", -1,
                               &select, nullptr),
            SQLITE_OK);
  ASSERT_EQ(sqlite3_step(select), SQLITE_ROW);
  const int64_t time_ns = sqlite3_column_int64(select, 0) + 5;
  const std::string kind(reinterpret_cast<const char*>(sqlite3_column_text(select, 1)));
  const std::string body(static_cast<const char*>(sqlite3_column_blob(select, 2)),
                         static_cast<size_t>(sqlite3_column_bytes(select, 2)));
  sqlite3_finalize(select);
  sqlite3_close(db);
  const int64_t checksum = static_cast<int64_t>(EventChecksum(9, time_ns, kind, body));
  Sql("UPDATE events SET time_ns = " + std::to_string(time_ns) +
      ", checksum = " + std::to_string(checksum) + " WHERE sequence = 9");
  const std::string refusal = Refusal();
  EXPECT_NE(refusal.find("event 9"), std::string::npos) << refusal;
  EXPECT_NE(refusal.find("disagrees"), std::string::npos) << refusal;
}

TEST_F(StoreIntegrityTest, DeletedRowsAreNamed) {
  Sql("DELETE FROM events WHERE sequence BETWEEN 40 AND 44");
  const std::string refusal = Refusal();
  EXPECT_NE(refusal.find("events 40..44 are missing"), std::string::npos) << refusal;
}

TEST_F(StoreIntegrityTest, DeletedNewestRowsAreCaughtByTheRecord) {
  Sql("DELETE FROM events WHERE sequence > 100");
  const std::string refusal = Refusal();
  EXPECT_NE(refusal.find("events 101..110 are missing"), std::string::npos) << refusal;
  EXPECT_NE(refusal.find("-wal"), std::string::npos) << refusal;
  EXPECT_NE(refusal.find("--annotations-accept-loss"), std::string::npos) << refusal;
  // Accepting the loss explicitly starts with what remains, and resets the record.
  AnnotationStoreOptions accept;
  accept.accept_lost_events = true;
  {
    std::unique_ptr<AnnotationStore> store = Open(accept);
    ASSERT_TRUE(store);
    EXPECT_EQ(store->last_sequence(), 100u);
  }
  std::unique_ptr<AnnotationStore> again = Open();
  ASSERT_TRUE(again);
  EXPECT_EQ(again->last_sequence(), 100u);
}

TEST_F(StoreIntegrityTest, OlderCopyOfTheDatabaseIsRefused) {
  // A copy taken now, then more events, then the copy put back over the database.
  const std::string copy = (dir_ / "copy.db").string();
  {
    std::unique_ptr<AnnotationStore> store = Open();  // closing checkpoints the WAL
  }
  fs::copy_file(db_, copy);
  {
    std::unique_ptr<AnnotationStore> store = Open();
    std::vector<wire::AnnotationEvent> more{Begin(99)};
    ASSERT_TRUE(store->Commit(&more).ok());
  }
  fs::copy_file(copy, db_, fs::copy_options::overwrite_existing);
  const std::string refusal = Refusal();
  EXPECT_NE(refusal.find("events 111..111 are missing"), std::string::npos) << refusal;
}

TEST_F(StoreIntegrityTest, AnotherDatabaseWithTheSameLengthIsRefused) {
  // Same number of events, different last event: the record's checksum differs.
  { std::unique_ptr<AnnotationStore> store = Open(); }
  Sql("UPDATE events SET body = body WHERE sequence = 1");  // no change: still opens
  { ASSERT_TRUE(Open()); }
  const std::string other = (dir_ / "b.db").string();
  {
    Expected<std::unique_ptr<AnnotationStore>> b = AnnotationStore::Open(other);
    ASSERT_TRUE(b.ok());
    std::vector<wire::AnnotationEvent> batch;
    for (uint64_t i = 1; i <= kEvents; ++i) batch.push_back(Begin(i));
    ASSERT_TRUE((*b)->Commit(&batch).ok());
  }
  fs::copy_file(other, db_, fs::copy_options::overwrite_existing);
  const std::string refusal = Refusal();
  EXPECT_NE(refusal.find("is not the one that was acknowledged"), std::string::npos) << refusal;
}

TEST_F(StoreIntegrityTest, MissingOrDamagedRecordIsRefused) {
  const std::string record = db_ + ".seq";
  fs::remove(record);
  std::string refusal = Refusal();
  EXPECT_NE(refusal.find("is missing or empty"), std::string::npos) << refusal;
  std::ofstream(record, std::ios::trunc) << "STSEQ1 garbage\n";
  refusal = Refusal();
  EXPECT_NE(refusal.find(record + " is damaged"), std::string::npos) << refusal;
  // One digit changed: the line's own checksum no longer matches.
  std::string line = SequenceRecordLine(SequenceMark{kEvents, 1});
  line[10] = '9';
  std::ofstream(record, std::ios::trunc) << line;
  refusal = Refusal();
  EXPECT_NE(refusal.find("is damaged"), std::string::npos) << refusal;
}

TEST_F(StoreIntegrityTest, SecondStoreOnTheSameFileIsRefusedWhileTheFirstIsOpen) {
  std::unique_ptr<AnnotationStore> first = Open();
  ASSERT_TRUE(first);
  const std::string refusal = Refusal();
  EXPECT_NE(refusal.find("in use by another coordinator (pid " + std::to_string(::getpid())),
            std::string::npos)
      << refusal;
  first.reset();
  EXPECT_TRUE(Open());
}

TEST_F(StoreIntegrityTest, Version1DatabaseIsUpgradedAndThenChecked) {
  // A version 1 file as the previous build wrote it: no checksum column, no record.
  fs::remove_all(dir_);
  fs::create_directories(dir_);
  std::string body;
  wire::AnnotationEvent e = Begin(5);
  e.set_event_sequence(1);
  e.set_time_ns(1234);
  e.SerializeToString(&body);
  std::string hex;
  for (unsigned char c : body) {
    static const char* digits = "0123456789abcdef";
    hex += digits[c >> 4];
    hex += digits[c & 15];
  }
  Sql("PRAGMA journal_mode=WAL; CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT);"
      "CREATE TABLE events(sequence INTEGER PRIMARY KEY, time_ns INTEGER NOT NULL, kind TEXT NOT "
      "NULL, body BLOB NOT NULL); INSERT INTO meta VALUES('schema_version', '1');"
      "INSERT INTO events VALUES(1, 1234, 'stroke_begin', x'" +
      hex + "');");
  {
    std::unique_ptr<AnnotationStore> store = Open();
    ASSERT_TRUE(store);
    EXPECT_EQ(store->last_sequence(), 1u);
  }
  std::unique_ptr<AnnotationStore> again = Open();
  ASSERT_TRUE(again);
  EXPECT_EQ(again->state().strokes().count(5), 1u);
}

TEST_F(StoreIntegrityTest, EventChecksumSeesEverySingleByteChange) {
  const std::string body = "\x0a\x05stroke points body";
  const uint64_t base = EventChecksum(3, 100, "stroke_points", body);
  for (size_t i = 0; i < body.size(); ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      std::string changed = body;
      changed[i] = static_cast<char>(changed[i] ^ (1 << bit));
      EXPECT_NE(EventChecksum(3, 100, "stroke_points", changed), base) << i << " " << bit;
    }
  }
  EXPECT_NE(EventChecksum(4, 100, "stroke_points", body), base);
  EXPECT_NE(EventChecksum(3, 101, "stroke_points", body), base);
  EXPECT_NE(EventChecksum(3, 100, "stroke_pointt", body), base);
}

}  // namespace
}  // namespace sandtable::coordinator
