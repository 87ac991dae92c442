#include "coordinator/annotations/annotation_store.h"

#include <sqlite3.h>

#include "proto/envelope_stamper.h"

namespace sandtable::coordinator {
namespace {

constexpr int kSchemaVersion = 1;

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
  sqlite3* db = nullptr;
  const int rc = sqlite3_open_v2(
      path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr);
  std::unique_ptr<AnnotationStore> store(new AnnotationStore(db, path));
  if (rc != SQLITE_OK) {
    return IoError("annotation database " + path +
                   ": cannot open: " + (db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc)));
  }
  sqlite3_extended_result_codes(db, 1);
  Status initialised = store->Initialise(options);
  if (!initialised.ok()) return initialised;
  Status replayed = store->Replay();
  if (!replayed.ok()) return replayed;
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
  ST_RETURN_IF_ERROR(Exec(
      "CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT);"
      "CREATE TABLE IF NOT EXISTS events(sequence INTEGER PRIMARY KEY, time_ns INTEGER NOT NULL,"
      " kind TEXT NOT NULL, body BLOB NOT NULL);"
      "INSERT OR IGNORE INTO meta(key, value) VALUES('schema_version', '" +
      std::to_string(kSchemaVersion) + "');"));
  Statement version(db_, "SELECT value FROM meta WHERE key = 'schema_version'");
  if (!version.ok() || sqlite3_step(version.get()) != SQLITE_ROW) return Error("schema_version");
  const int found = sqlite3_column_int(version.get(), 0);
  if (found != kSchemaVersion) {
    return ParseError("annotation database " + path_ + " has schema version " +
                      std::to_string(found) + "; this build reads version " +
                      std::to_string(kSchemaVersion));
  }
  return OkStatus();
}

Status AnnotationStore::Replay() {
  Statement select(db_, "SELECT sequence, body FROM events ORDER BY sequence");
  if (!select.ok()) return Error("reading events");
  int rc;
  while ((rc = sqlite3_step(select.get())) == SQLITE_ROW) {
    const int64_t sequence = sqlite3_column_int64(select.get(), 0);
    const void* blob = sqlite3_column_blob(select.get(), 1);
    const int bytes = sqlite3_column_bytes(select.get(), 1);
    wire::AnnotationEvent event;
    if (!event.ParseFromArray(blob, bytes) ||
        event.event_sequence() != static_cast<uint64_t>(sequence) || sequence <= 0 ||
        static_cast<uint64_t>(sequence) <= state_.last_sequence()) {
      return ParseError("annotation database " + path_ + ": event " + std::to_string(sequence) +
                        " does not parse or its sequence is inconsistent; the file is damaged");
    }
    Status checked = state_.Check(event);
    if (!checked.ok()) {
      return ParseError("annotation database " + path_ + ": event " + std::to_string(sequence) +
                        " does not apply: " + checked.message());
    }
    state_.Apply(event);
    ++events_loaded_;
  }
  if (rc != SQLITE_DONE) return Error("reading events");
  return OkStatus();
}

Expected<CommitReport> AnnotationStore::Commit(std::vector<wire::AnnotationEvent>* events) {
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
    Status replayed = Replay();
    if (!replayed.ok()) return replayed.WithContext(error.message() + "; then");
    (void)before;
    return error;
  };
  Statement insert(db_, "INSERT INTO events(sequence, time_ns, kind, body) VALUES(?, ?, ?, ?)");
  if (!insert.ok()) return fail(Error("prepare insert"));
  const int64_t now_ns = proto::SteadyNowNs();
  std::string body;
  for (size_t i = 0; i < events->size(); ++i) {
    wire::AnnotationEvent& event = (*events)[i];
    report.results[i] = state_.Check(event);
    if (!report.results[i].ok()) continue;
    event.set_event_sequence(state_.last_sequence() + 1);
    event.set_time_ns(now_ns);
    body.clear();
    event.SerializeToString(&body);
    sqlite3_bind_int64(insert.get(), 1, static_cast<int64_t>(event.event_sequence()));
    sqlite3_bind_int64(insert.get(), 2, event.time_ns());
    sqlite3_bind_text(insert.get(), 3, AnnotationKindName(event), -1, SQLITE_STATIC);
    sqlite3_bind_blob(insert.get(), 4, body.data(), static_cast<int>(body.size()),
                      SQLITE_TRANSIENT);
    if (sqlite3_step(insert.get()) != SQLITE_DONE) {
      return fail(Error("insert event " + std::to_string(event.event_sequence())));
    }
    sqlite3_reset(insert.get());
    state_.Apply(event);
    ++report.num_committed;
  }
  // COMMIT returns after the WAL frames are written (and fsynced with synchronous=FULL).
  Status committed = Exec("COMMIT");
  if (!committed.ok()) return fail(committed);
  return report;
}

Expected<std::vector<wire::AnnotationEvent>> AnnotationStore::EventsAfter(SequenceNumber after,
                                                                          size_t limit) const {
  std::vector<wire::AnnotationEvent> out;
  Statement select(db_, "SELECT body FROM events WHERE sequence > ? ORDER BY sequence LIMIT ?");
  if (!select.ok()) return Error("select events");
  sqlite3_bind_int64(select.get(), 1, static_cast<int64_t>(after));
  sqlite3_bind_int64(select.get(), 2, static_cast<int64_t>(limit));
  int rc;
  while ((rc = sqlite3_step(select.get())) == SQLITE_ROW) {
    wire::AnnotationEvent event;
    if (!event.ParseFromArray(sqlite3_column_blob(select.get(), 0),
                              sqlite3_column_bytes(select.get(), 0))) {
      return ParseError("annotation database " + path_ + ": an event does not parse");
    }
    out.push_back(std::move(event));
  }
  if (rc != SQLITE_DONE) return Error("select events");
  return out;
}

}  // namespace sandtable::coordinator
