#include "coordinator/annotations/annotation_store.h"

#include <sqlite3.h>

#include <filesystem>

#include "common/base/file_io.h"
#include "common/base/log.h"
#include "coordinator/annotations/event_checksum.h"
#include "proto/envelope_stamper.h"

namespace sandtable::coordinator {
namespace {

constexpr int kSchemaVersion = 2;

// What to do when acknowledged events are missing (a lost -wal, an older copy).
std::string LostAdvice(const std::string& path) {
  return ". To recover: restore " + path +
         " together with its -wal file from a backup, or "
         "import the latest session export into a new database (--annotations NEW.db "
         "--import-session FILE.jsonl); to go on with the events that remain, start once with "
         "--annotations-accept-loss (the loss is logged and the record reset)";
}

// What to do when a stored row was changed.
std::string ChangedAdvice(const std::string& path) {
  return ". The file was damaged or edited outside the coordinator. To recover: move " + path +
         " aside (keep it for inspection) and restore it from a backup, or import the latest "
         "session export into a new database (--annotations NEW.db --import-session "
         "FILE.jsonl)";
}

std::string Column(sqlite3_stmt* stmt, int i) {
  const void* bytes = sqlite3_column_blob(stmt, i);
  const int n = sqlite3_column_bytes(stmt, i);
  return bytes != nullptr ? std::string(static_cast<const char*>(bytes), static_cast<size_t>(n))
                          : std::string();
}

// RAII for prepared statements.
class Statement {
 public:
  Statement(sqlite3* db, const char* sql) {
    rc_ = sqlite3_prepare_v2(db, sql, -1, &stmt_, nullptr);
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  bool ok() const { return rc_ == SQLITE_OK; }
  sqlite3_stmt* get() { return stmt_; }

 private:
  sqlite3_stmt* stmt_ = nullptr;
  int rc_;
};

}  // namespace

const char* AnnotationKindName(const wire::AnnotationEvent& event) {
  switch (event.kind_case()) {
    case wire::AnnotationEvent::kStrokeBegin:
      return "stroke_begin";
    case wire::AnnotationEvent::kStrokePoints:
      return "stroke_points";
    case wire::AnnotationEvent::kStrokeEnd:
      return "stroke_end";
    case wire::AnnotationEvent::kErase:
      return "erase";
    case wire::AnnotationEvent::kClear:
      return "clear";
    case wire::AnnotationEvent::kSpotErase:
      return "spot_erase";
    case wire::AnnotationEvent::KIND_NOT_SET:
      break;
  }
  return "none";
}

Expected<std::unique_ptr<AnnotationStore>> AnnotationStore::Open(
    const std::string& path, const AnnotationStoreOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  std::optional<SequenceRecord> record;
  if (path != ":memory:") {
    for (const std::string& file : {path, path + "-wal"}) {
      std::error_code error;
      if (std::filesystem::exists(std::filesystem::symlink_status(file, error))) {
        ST_RETURN_IF_ERROR(
            CheckInputFile(file, kMaxAnnotationDatabaseBytes, "kMaxAnnotationDatabaseBytes"));
      }
    }
    // The lock before SQLite: a second coordinator must not even open (and recover) the
    // database.
    Expected<SequenceRecord> acquired = SequenceRecord::Acquire(path);
    if (!acquired.ok()) return acquired.status();
    record.emplace(std::move(*acquired));
  }
  sqlite3* db = nullptr;
  const int rc = sqlite3_open_v2(
      path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr);
  std::unique_ptr<AnnotationStore> store(new AnnotationStore(db, path));
  store->record_ = std::move(record);
  store->sync_full_ = options.sync == SyncMode::kFull;
  if (rc != SQLITE_OK) {
    return IoError("annotation database " + path +
                   ": cannot open: " + (db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc)));
  }
  sqlite3_extended_result_codes(db, 1);
  Status initialised = store->Initialise(options);
  if (!initialised.ok()) return initialised;
  Status replayed = store->Replay();
  if (!replayed.ok()) return replayed;
  Status recorded = store->VerifyRecord(options);
  if (!recorded.ok()) return recorded;
  return store;
}

AnnotationStore::~AnnotationStore() { sqlite3_close_v2(db_); }

Status AnnotationStore::Error(const std::string& what) const {
  const int code = sqlite3_errcode(db_);
  std::string advice;
  if ((code & 0xff) == SQLITE_NOTADB || (code & 0xff) == SQLITE_CORRUPT) {
    advice =
        "; the file is damaged or not an annotation database: move it aside (keep it for "
        "inspection) and start with a new file, or import a session export";
  }
  return ParseError("annotation database " + path_ + ": " + what + ": " + sqlite3_errmsg(db_) +
                    " (sqlite code " + std::to_string(code) + ")" + advice);
}

Status AnnotationStore::Exec(const std::string& sql) {
  char* message = nullptr;
  const int rc = sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &message);
  sqlite3_free(message);
  if (rc != SQLITE_OK) return Error(sql);
  return OkStatus();
}

Status AnnotationStore::Initialise(const AnnotationStoreOptions& options) {
  // Wait a little for a lock held by another process instead of failing at once.
  sqlite3_busy_timeout(db_, 2000);
  // The first statement that reads the header detects a file that is not a database.
  ST_RETURN_IF_ERROR(Exec("PRAGMA journal_mode=WAL"));
  ST_RETURN_IF_ERROR(Exec(options.sync == SyncMode::kFull ? "PRAGMA synchronous=FULL"
                                                          : "PRAGMA synchronous=NORMAL"));
  {
    Statement check(db_, "PRAGMA quick_check");
    if (!check.ok()) return Error("quick_check");
    const int rc = sqlite3_step(check.get());
    if (rc != SQLITE_ROW) return Error("quick_check");
    const std::string result = reinterpret_cast<const char*>(sqlite3_column_text(check.get(), 0));
    if (result != "ok") {
      return ParseError("annotation database " + path_ + " is damaged (quick_check: " + result +
                        "): move it aside and start with a new file, or import a session export");
    }
  }
  bool has_meta = false;
  {
    Statement tables(db_, "SELECT count(*) FROM sqlite_master WHERE type='table' AND name='meta'");
    if (!tables.ok() || sqlite3_step(tables.get()) != SQLITE_ROW) return Error("reading schema");
    has_meta = sqlite3_column_int(tables.get(), 0) > 0;
  }
  if (!has_meta) return CreateSchema();
  Statement version(db_, "SELECT value FROM meta WHERE key = 'schema_version'");
  if (!version.ok() || sqlite3_step(version.get()) != SQLITE_ROW) return Error("schema_version");
  const int found = sqlite3_column_int(version.get(), 0);
  if (found == 1) return UpgradeFromVersion1();
  if (found != kSchemaVersion) {
    return ParseError("annotation database " + path_ + " has schema version " +
                      std::to_string(found) + "; this build reads versions 1 and " +
                      std::to_string(kSchemaVersion));
  }
  return OkStatus();
}

Status AnnotationStore::CreateSchema() {
  ST_RETURN_IF_ERROR(
      Exec("BEGIN IMMEDIATE;"
           "CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT);"
           "CREATE TABLE events(sequence INTEGER PRIMARY KEY, time_ns INTEGER NOT NULL,"
           " kind TEXT NOT NULL, body BLOB NOT NULL, checksum INTEGER NOT NULL);"
           "INSERT INTO meta(key, value) VALUES('schema_version', '" +
           std::to_string(kSchemaVersion) + "');COMMIT;"));
  // Into the main file at once: a -wal lost later cannot take the schema with it.
  return Exec("PRAGMA wal_checkpoint(TRUNCATE)");
}

// Version 1 had no checksum column: add it and checksum the rows as they are (they are then
// verified like any others by Replay()).
Status AnnotationStore::UpgradeFromVersion1() {
  ST_RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE; ALTER TABLE events ADD COLUMN checksum INTEGER"));
  auto fail = [&](Status error) {
    (void)Exec("ROLLBACK");
    return error;
  };
  {
    Statement select(db_, "SELECT sequence, time_ns, kind, body FROM events");
    Statement update(db_, "UPDATE events SET checksum = ? WHERE sequence = ?");
    if (!select.ok() || !update.ok()) return fail(Error("upgrading from schema version 1"));
    int rc;
    while ((rc = sqlite3_step(select.get())) == SQLITE_ROW) {
      const int64_t sequence = sqlite3_column_int64(select.get(), 0);
      const uint64_t checksum = EventChecksum(sequence, sqlite3_column_int64(select.get(), 1),
                                              Column(select.get(), 2), Column(select.get(), 3));
      sqlite3_bind_int64(update.get(), 1, static_cast<int64_t>(checksum));
      sqlite3_bind_int64(update.get(), 2, sequence);
      if (sqlite3_step(update.get()) != SQLITE_DONE) return fail(Error("upgrading a row"));
      sqlite3_reset(update.get());
    }
    if (rc != SQLITE_DONE) return fail(Error("upgrading from schema version 1"));
  }
  ST_RETURN_IF_ERROR(Exec("UPDATE meta SET value = '" + std::to_string(kSchemaVersion) +
                          "' WHERE key = 'schema_version'; COMMIT"));
  upgraded_ = true;
  ST_LOG(kInfo) << "annotation database " << path_ << ": upgraded from schema version 1 to "
                << kSchemaVersion << " (a checksum per event)";
  return OkStatus();
}

Status AnnotationStore::Replay() {
  Statement select(db_,
                   "SELECT sequence, time_ns, kind, body, checksum FROM events ORDER BY sequence");
  if (!select.ok()) return Error("reading events");
  last_checksum_ = 0;
  int rc;
  while ((rc = sqlite3_step(select.get())) == SQLITE_ROW) {
    const int64_t sequence = sqlite3_column_int64(select.get(), 0);
    const int64_t time_ns = sqlite3_column_int64(select.get(), 1);
    const std::string kind = Column(select.get(), 2);
    const std::string body = Column(select.get(), 3);
    const std::string where = "annotation database " + path_ + ": event " +
                              std::to_string(sequence) + " (kind " + kind + ")";
    const SequenceNumber expected = state_.last_sequence() + 1;
    if (sequence <= 0 || static_cast<uint64_t>(sequence) != expected) {
      return ParseError("annotation database " + path_ + ": events " + std::to_string(expected) +
                        ".." + std::to_string(sequence - 1) +
                        " are missing from the log (the next row holds event " +
                        std::to_string(sequence) + "): rows were deleted" + ChangedAdvice(path_));
    }
    if (sqlite3_column_type(select.get(), 4) != SQLITE_INTEGER) {
      return ParseError(where + " has no checksum" + ChangedAdvice(path_));
    }
    const uint64_t stored = static_cast<uint64_t>(sqlite3_column_int64(select.get(), 4));
    const uint64_t computed = EventChecksum(sequence, time_ns, kind, body);
    if (stored != computed) {
      return ParseError(where +
                        ": checksum mismatch (a field of the row - sequence, time, kind, ids or "
                        "point coordinates - was changed after it was written)" +
                        ChangedAdvice(path_));
    }
    wire::AnnotationEvent event;
    if (!event.ParseFromString(body) || event.event_sequence() != static_cast<uint64_t>(sequence) ||
        event.time_ns() != time_ns || kind != AnnotationKindName(event)) {
      return ParseError(where +
                        ": the body does not parse or disagrees with the row's sequence, time_ns "
                        "or kind" +
                        ChangedAdvice(path_));
    }
    Status checked = state_.Check(event);
    if (!checked.ok()) {
      return ParseError(where + " does not apply: " + checked.message() + ChangedAdvice(path_));
    }
    state_.Apply(event);
    last_checksum_ = computed;
    ++events_loaded_;
  }
  if (rc != SQLITE_DONE) return Error("reading events");
  return OkStatus();
}

Status AnnotationStore::VerifyRecord(const AnnotationStoreOptions& options) {
  if (!record_) return OkStatus();
  const SequenceNumber last = state_.last_sequence();
  const std::string db =
      "annotation database " + path_ +
      (last == 0 ? std::string(" (no events)") : " (events 1.." + std::to_string(last) + ")");
  std::string problem;
  Expected<std::optional<SequenceMark>> mark = record_->Read();
  if (!mark.ok()) {
    problem = mark.status().message();
  } else if (!mark->has_value()) {
    if (last > 0 && !upgraded_) {
      problem = "the sequence record " + record_->record_path() + " is missing or empty but " + db +
                " holds events: the record was deleted, or the database was copied "
                "without it";
    }
  } else if ((*mark)->sequence > last) {
    problem = db + ": the sequence record " + record_->record_path() + " says " +
              std::to_string((*mark)->sequence) + " events were acknowledged, so events " +
              std::to_string(last + 1) + ".." + std::to_string((*mark)->sequence) +
              " are missing: its -wal file was deleted, truncated or damaged, or the database "
              "was replaced by an older copy";
  } else if ((*mark)->sequence > 0) {
    Statement select(db_, "SELECT checksum FROM events WHERE sequence = ?");
    if (!select.ok()) return Error("reading the recorded event");
    sqlite3_bind_int64(select.get(), 1, static_cast<int64_t>((*mark)->sequence));
    if (sqlite3_step(select.get()) != SQLITE_ROW ||
        static_cast<uint64_t>(sqlite3_column_int64(select.get(), 0)) != (*mark)->checksum) {
      problem = db + ": event " + std::to_string((*mark)->sequence) +
                " is not the one that was acknowledged (its checksum differs from the record " +
                record_->record_path() +
                "): the database was replaced by another one, or its -wal by an older one";
    }
  }
  if (!problem.empty()) {
    if (!options.accept_lost_events) return ParseError(problem + LostAdvice(path_));
    ST_LOG(kError) << problem << "; ACCEPTED (--annotations-accept-loss): going on with events 1.."
                   << last << ", the record is reset";
  }
  Status written = record_->Write(SequenceMark{last, last_checksum_}, sync_full_);
  if (!written.ok()) return written;
  return OkStatus();
}

void AnnotationStore::WriteRecord() {
  if (!record_) return;
  Status written = record_->Write(SequenceMark{state_.last_sequence(), last_checksum_}, sync_full_);
  if (!written.ok()) {
    if (record_write_failures_++ == 0) {
      ST_LOG(kError) << written.ToString()
                     << " (the events are committed; a later loss of the -wal file may go "
                        "undetected until the record is written again)";
    }
  }
}

Expected<CommitReport> AnnotationStore::Commit(std::vector<wire::AnnotationEvent>* events,
                                               bool all_or_nothing) {
  CommitReport report;
  report.results.resize(events->size());
  if (events->empty()) return report;
  const SequenceNumber before = state_.last_sequence();
  ST_RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE"));
  // Checked and applied in place (no copy of the state per commit); if the transaction fails
  // the state is rebuilt from disk below, so it never runs ahead of what is durable.
  auto fail = [&](Status error) -> Status {
    (void)Exec("ROLLBACK");
    state_ = cluster::AnnotationState();
    events_loaded_ = 0;
    last_checksum_ = 0;
    Status replayed = Replay();
    if (!replayed.ok()) return replayed.WithContext(error.message() + "; then");
    (void)before;
    return error;
  };
  Statement insert(
      db_, "INSERT INTO events(sequence, time_ns, kind, body, checksum) VALUES(?, ?, ?, ?, ?)");
  if (!insert.ok()) return fail(Error("prepare insert"));
  const int64_t now_ns = proto::SteadyNowNs();
  std::string body;
  for (size_t i = 0; i < events->size(); ++i) {
    wire::AnnotationEvent& event = (*events)[i];
    report.results[i] = state_.Check(event);
    if (!report.results[i].ok()) {
      if (!all_or_nothing) continue;
      return fail(report.results[i].WithContext("event " + std::to_string(i + 1) +
                                                " of the batch (nothing committed)"));
    }
    event.set_event_sequence(state_.last_sequence() + 1);
    event.set_time_ns(now_ns);
    body.clear();
    event.SerializeToString(&body);
    sqlite3_bind_int64(insert.get(), 1, static_cast<int64_t>(event.event_sequence()));
    sqlite3_bind_int64(insert.get(), 2, event.time_ns());
    const char* kind = AnnotationKindName(event);
    const uint64_t checksum =
        EventChecksum(static_cast<int64_t>(event.event_sequence()), event.time_ns(), kind, body);
    sqlite3_bind_text(insert.get(), 3, kind, -1, SQLITE_STATIC);
    sqlite3_bind_blob(insert.get(), 4, body.data(), static_cast<int>(body.size()),
                      SQLITE_TRANSIENT);
    sqlite3_bind_int64(insert.get(), 5, static_cast<int64_t>(checksum));
    if (sqlite3_step(insert.get()) != SQLITE_DONE) {
      return fail(Error("insert event " + std::to_string(event.event_sequence())));
    }
    sqlite3_reset(insert.get());
    state_.Apply(event);
    last_checksum_ = checksum;
    ++report.num_committed;
  }
  // COMMIT returns after the WAL frames are written (and fsynced with synchronous=FULL).
  Status committed = Exec("COMMIT");
  if (!committed.ok()) return fail(committed);
  // Then the record, before the caller acknowledges anything of this batch.
  if (report.num_committed > 0) WriteRecord();
  return report;
}

Expected<std::vector<wire::AnnotationEvent>> AnnotationStore::EventsAfter(SequenceNumber after,
                                                                          size_t limit) const {
  std::vector<wire::AnnotationEvent> out;
  Statement select(db_,
                   "SELECT sequence, time_ns, kind, body, checksum FROM events WHERE sequence > ? "
                   "ORDER BY sequence LIMIT ?");
  if (!select.ok()) return Error("select events");
  sqlite3_bind_int64(select.get(), 1, static_cast<int64_t>(after));
  sqlite3_bind_int64(select.get(), 2, static_cast<int64_t>(limit));
  int rc;
  while ((rc = sqlite3_step(select.get())) == SQLITE_ROW) {
    const int64_t sequence = sqlite3_column_int64(select.get(), 0);
    const std::string body = Column(select.get(), 3);
    wire::AnnotationEvent event;
    if (static_cast<uint64_t>(sqlite3_column_int64(select.get(), 4)) !=
            EventChecksum(sequence, sqlite3_column_int64(select.get(), 1), Column(select.get(), 2),
                          body) ||
        !event.ParseFromString(body)) {
      return ParseError("annotation database " + path_ + ": event " + std::to_string(sequence) +
                        " was changed on disk since the start (checksum mismatch)");
    }
    out.push_back(std::move(event));
  }
  if (rc != SQLITE_DONE) return Error("select events");
  return out;
}

}  // namespace sandtable::coordinator
