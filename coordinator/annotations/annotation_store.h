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
// Schema (version 1):
//   meta(key TEXT PRIMARY KEY, value TEXT)        -- "schema_version" = "1"
//   events(sequence INTEGER PRIMARY KEY, time_ns INTEGER, kind TEXT, body BLOB)
// body is the serialized wire::AnnotationEvent (sequence included).
// Failure: Open() of a file that is not a SQLite database, of a damaged database (quick_check
// fails), of a newer schema, or holding an event that does not parse or does not apply,
// returns an error naming the file and what to do; never aborts. Not thread-safe.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "cluster/annotation_state.h"
#include "common/base/status.h"
#include "proto/events.pb.h"

struct sqlite3;

namespace sandtable::coordinator {

enum class SyncMode { kFull, kNormal };

struct AnnotationStoreOptions {
  SyncMode sync = SyncMode::kFull;
  Status Check() const { return OkStatus(); }
};

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
  Expected<CommitReport> Commit(std::vector<wire::AnnotationEvent>* events);

  // Events with sequence > `after`, oldest first, at most `limit`.
  Expected<std::vector<wire::AnnotationEvent>> EventsAfter(SequenceNumber after,
                                                           size_t limit) const;

  const cluster::AnnotationState& state() const { return state_; }
  SequenceNumber last_sequence() const { return state_.last_sequence(); }
  const std::string& path() const { return path_; }
  uint64_t events_loaded() const { return events_loaded_; }

 private:
  AnnotationStore(sqlite3* db, std::string path) : db_(db), path_(std::move(path)) {}
  Status Initialise(const AnnotationStoreOptions& options);
  Status Replay();
  Status Exec(const std::string& sql);
  Status Error(const std::string& what) const;

  sqlite3* db_;
  std::string path_;
  cluster::AnnotationState state_;
  uint64_t events_loaded_ = 0;
};

// The event kind as stored in events.kind ("stroke_begin", ...).
const char* AnnotationKindName(const wire::AnnotationEvent& event);

}  // namespace sandtable::coordinator
