// AnnotationStore: the durable, sequenced log of annotation events (SQLite) and the state it
// rebuilds.
//
// Contract: Commit() assigns the next sequence numbers to a batch of checked events, writes
// them in ONE SQLite transaction and returns only after the commit; only then may the caller
// acknowledge or publish them (write-ahead: an acknowledged event is on disk). Journal: WAL.
// Synchronous: FULL by default (the commit is fsynced before Commit() returns, so an
// acknowledged event survives a process kill AND a power cut or kernel crash); NORMAL survives
// a process kill (SIGKILL) but may lose the last transactions on power loss; it is offered
// for sites on slow disks (measured costs in docs/coordinator.md).
// Schema (version 2):
//   meta(key TEXT PRIMARY KEY, value TEXT)   -- "schema_version" = "2"
//   events(sequence INTEGER PRIMARY KEY, time_ns INTEGER, kind TEXT, body BLOB,
//          checksum INTEGER)                 -- EventChecksum of the other four columns
// body is the serialized wire::AnnotationEvent (sequence and time_ns included). A version 1
// database (no checksum column) is upgraded in place at open, in one transaction.
// Integrity, checked at Open() (docs/reliability.md):
//   - every row: its checksum (event_checksum.h) over sequence, time_ns, kind and body; body
//     parses; body's sequence, time and kind equal the columns; sequences are 1, 2, 3 ... with
//     no gap; every event applies to the state of those before it;
//   - the log against PATH.seq (sequence_record.h), the last acknowledged sequence written
//     beside the database after every commit and before any acknowledgement: the database must
//     hold that event, with the recorded checksum. A deleted, truncated or damaged -wal file
//     (or an older copy of the database) leaves the log short of the record.
//   - PATH.lock: a second store (another coordinator) on the same file is refused.
// Failure: Open() of a file that is not a SQLite database, of a damaged database (quick_check
// fails), of a newer schema, of a changed or missing row, or of a log shorter than the record,
// returns an error naming the file, the event and what to do; never aborts. Only the loss of
// acknowledged events (and a missing or damaged record) may be accepted, explicitly, with
// AnnotationStoreOptions::accept_lost_events (logged, the record then reset); a changed row
// never is. Not thread-safe. ":memory:" keeps no side files.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cluster/annotation_state.h"
#include "common/base/status.h"
#include "coordinator/annotations/sequence_record.h"
#include "proto/events.pb.h"

struct sqlite3;

namespace sandtable::coordinator {

enum class SyncMode { kFull, kNormal };

struct AnnotationStoreOptions {
  SyncMode sync = SyncMode::kFull;
  // Start even though the record says acknowledged events are missing (after a lost -wal,
  // or a database restored from an older backup on purpose): logged as an error naming the
  // lost sequences, and the record is reset to the database's last event.
  bool accept_lost_events = false;
  Status Check() const { return OkStatus(); }
};

// Bound of a database file opened by the store (CheckInputFile): 64 GiB.
inline constexpr uint64_t kMaxAnnotationDatabaseBytes = uint64_t{64} << 30;

struct CommitReport {
  // One per event of the batch: OK (the event now holds its event_sequence and time_ns), or
  // why it was rejected (it does not apply to the state; nothing written for it).
  std::vector<Status> results;
  size_t num_committed = 0;
};

class AnnotationStore {
 public:
  // Opens (creating when absent) the database at `path` and replays it into state().
  static Expected<std::unique_ptr<AnnotationStore>> Open(
      const std::string& path, const AnnotationStoreOptions& options = {});
  ~AnnotationStore();
  AnnotationStore(const AnnotationStore&) = delete;
  AnnotationStore& operator=(const AnnotationStore&) = delete;

  // Checks `events` in order against the state (each seeing the ones before it), then
  // sequences, persists (one transaction) and applies those that pass. An error return means
  // the transaction failed (disk full, I/O error): nothing of the batch is durable, and the
  // state is rebuilt from the database, so it again equals what is on disk.
  // After the commit the sequence record is rewritten (fdatasync with SyncMode::kFull); a
  // failure to write it is logged and counted (record_write_failures), the events stay
  // committed. With `all_or_nothing`, an event that does not apply rolls back the whole batch
  // and comes back as INVALID_ARGUMENT naming its index.
  Expected<CommitReport> Commit(std::vector<wire::AnnotationEvent>* events,
                                bool all_or_nothing = false);

  // Events with sequence > `after`, oldest first, at most `limit`.
  Expected<std::vector<wire::AnnotationEvent>> EventsAfter(SequenceNumber after,
                                                           size_t limit) const;

  const cluster::AnnotationState& state() const { return state_; }
  SequenceNumber last_sequence() const { return state_.last_sequence(); }
  const std::string& path() const { return path_; }
  uint64_t events_loaded() const { return events_loaded_; }
  uint64_t record_write_failures() const { return record_write_failures_; }

 private:
  AnnotationStore(sqlite3* db, std::string path) : db_(db), path_(std::move(path)) {}
  Status Initialise(const AnnotationStoreOptions& options);
  Status CreateSchema();
  Status UpgradeFromVersion1();
  Status Replay();
  Status VerifyRecord(const AnnotationStoreOptions& options);
  void WriteRecord();
  Status Exec(const std::string& sql);
  Status Error(const std::string& what) const;

  sqlite3* db_;
  std::string path_;
  std::optional<SequenceRecord> record_;  // absent for ":memory:"
  bool sync_full_ = true;
  bool upgraded_ = false;  // a version 1 file was upgraded at this open (no record yet)
  uint64_t last_checksum_ = 0;
  cluster::AnnotationState state_;
  uint64_t events_loaded_ = 0;
  uint64_t record_write_failures_ = 0;
};

// The event kind as stored in events.kind ("stroke_begin", ...).
const char* AnnotationKindName(const wire::AnnotationEvent& event);

}  // namespace sandtable::coordinator
