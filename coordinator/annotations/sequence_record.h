// SequenceRecord: the two side files of an annotation database at PATH.
//
// - PATH.lock: held with flock(LOCK_EX) for as long as the store is open, so a second
//   coordinator on the same database is refused at start (it holds the first one's pid, for
//   the message). The kernel drops the lock when the process dies (SIGKILL included).
// - PATH.seq: the record of the last acknowledged sequence: one fixed-size line
//     "STSEQ1 <sequence, 20 digits> <checksum of that event, 16 hex> <FNV-1a of the line, 16 hex>"
//   rewritten in place (one pwrite of 62 bytes; fdatasync when `sync`) after every commit and
//   before any acknowledgement. It lives outside the database and its -wal file, so a deleted,
//   truncated or damaged -wal (which takes the newest events with it) leaves a record that is
//   ahead of the database: the store refuses to start (annotation_store.h).
// Failure: IO errors and a record that does not parse come back as Status naming the file;
// never aborts. Not thread-safe; one per open store.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "common/base/status.h"

namespace sandtable::coordinator {

struct SequenceMark {
  uint64_t sequence = 0;
  uint64_t checksum = 0;  // EventChecksum of the event `sequence` (0 when sequence is 0)
};

class SequenceRecord {
 public:
  // Takes the lock PATH.lock (UNAVAILABLE naming the holder's pid when another process has it)
  // and opens PATH.seq (created empty when absent).
  static Expected<SequenceRecord> Acquire(const std::string& database_path);
  SequenceRecord(SequenceRecord&& other) noexcept;
  SequenceRecord& operator=(SequenceRecord&& other) noexcept;
  SequenceRecord(const SequenceRecord&) = delete;
  SequenceRecord& operator=(const SequenceRecord&) = delete;
  ~SequenceRecord();

  // The mark as stored: nullopt when the file is empty (never written); PARSE_ERROR when it
  // holds anything but one well-formed line.
  Expected<std::optional<SequenceMark>> Read() const;
  Status Write(const SequenceMark& mark, bool sync);

  const std::string& record_path() const { return record_path_; }
  const std::string& lock_path() const { return lock_path_; }

 private:
  SequenceRecord() = default;
  void Close();

  std::string record_path_, lock_path_;
  int lock_fd_ = -1;
  int record_fd_ = -1;
};

// The record line for `mark` (62 bytes with the newline); exposed for tests.
std::string SequenceRecordLine(const SequenceMark& mark);

}  // namespace sandtable::coordinator
