#include "coordinator/annotations/sequence_record.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <utility>

#include "coordinator/annotations/event_checksum.h"

namespace sandtable::coordinator {
namespace {

constexpr size_t kRecordBytes = 62;
constexpr size_t kMaxRecordFileBytes = 4096;

std::string Errno() { return std::strerror(errno); }

std::string ReadSmallFile(int fd) {
  std::string text(kMaxRecordFileBytes, '\0');
  ssize_t n = ::pread(fd, text.data(), text.size(), 0);
  text.resize(n > 0 ? static_cast<size_t>(n) : 0);
  return text;
}

}  // namespace

std::string SequenceRecordLine(const SequenceMark& mark) {
  char prefix[64];
  std::snprintf(prefix, sizeof(prefix), "STSEQ1 %020" PRIu64 " %016" PRIx64, mark.sequence,
                mark.checksum);
  char line[96];
  std::snprintf(line, sizeof(line), "%s %016" PRIx64 "\n", prefix, Fnv1a64(prefix));
  return line;
}

Expected<SequenceRecord> SequenceRecord::Acquire(const std::string& database_path) {
  SequenceRecord record;
  record.lock_path_ = database_path + ".lock";
  record.record_path_ = database_path + ".seq";
  record.lock_fd_ = ::open(record.lock_path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (record.lock_fd_ < 0) {
    return IoError("annotation database lock " + record.lock_path_ + ": cannot open: " + Errno());
  }
  if (::flock(record.lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    const bool busy = errno == EWOULDBLOCK;
    std::string holder = ReadSmallFile(record.lock_fd_);
    while (!holder.empty() && (holder.back() == '\n' || holder.back() == '\0')) holder.pop_back();
    if (!busy) {
      return IoError("annotation database lock " + record.lock_path_ + ": flock: " + Errno());
    }
    return UnavailableError(
        "annotation database " + database_path + " is in use by another coordinator (" +
        (holder.empty() ? std::string("pid unknown") : holder) + ", lock " + record.lock_path_ +
        "): stop that coordinator first, or give this one another "
        "--annotations file");
  }
  const std::string pid = "pid " + std::to_string(::getpid()) + "\n";
  if (::ftruncate(record.lock_fd_, 0) != 0 ||
      ::pwrite(record.lock_fd_, pid.data(), pid.size(), 0) != static_cast<ssize_t>(pid.size())) {
    return IoError("annotation database lock " + record.lock_path_ + ": write: " + Errno());
  }
  struct stat st {};
  if (::lstat(record.record_path_.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    return IoError("annotation sequence record " + record.record_path_ +
                   " is not a regular file: move it aside");
  }
  record.record_fd_ =
      ::open(record.record_path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
  if (record.record_fd_ < 0) {
    return IoError("annotation sequence record " + record.record_path_ +
                   ": cannot open: " + Errno());
  }
  return record;
}

SequenceRecord::SequenceRecord(SequenceRecord&& other) noexcept { *this = std::move(other); }

SequenceRecord& SequenceRecord::operator=(SequenceRecord&& other) noexcept {
  if (this != &other) {
    Close();
    record_path_ = std::move(other.record_path_);
    lock_path_ = std::move(other.lock_path_);
    lock_fd_ = std::exchange(other.lock_fd_, -1);
    record_fd_ = std::exchange(other.record_fd_, -1);
  }
  return *this;
}

SequenceRecord::~SequenceRecord() { Close(); }

void SequenceRecord::Close() {
  if (record_fd_ >= 0) ::close(record_fd_);
  if (lock_fd_ >= 0) ::close(lock_fd_);  // releases the flock
  record_fd_ = lock_fd_ = -1;
}

Expected<std::optional<SequenceMark>> SequenceRecord::Read() const {
  struct stat st {};
  if (::fstat(record_fd_, &st) != 0) {
    return IoError("annotation sequence record " + record_path_ + ": stat: " + Errno());
  }
  if (st.st_size == 0) return std::optional<SequenceMark>();
  const std::string text = ReadSmallFile(record_fd_);
  SequenceMark mark;
  unsigned long long sequence = 0, checksum = 0, line_checksum = 0;
  int consumed = 0;
  const bool parsed = text.size() == kRecordBytes &&
                      std::sscanf(text.c_str(), "STSEQ1 %20llu %16llx %16llx\n%n", &sequence,
                                  &checksum, &line_checksum, &consumed) == 3;
  mark.sequence = sequence;
  mark.checksum = checksum;
  if (!parsed || SequenceRecordLine(mark) != text) {
    return ParseError("annotation sequence record " + record_path_ +
                      " is damaged (expected one line \"STSEQ1 <sequence> <checksum> "
                      "<line checksum>\" of " +
                      std::to_string(kRecordBytes) + " bytes, found " + std::to_string(st.st_size) +
                      " bytes)");
  }
  return std::optional<SequenceMark>(mark);
}

Status SequenceRecord::Write(const SequenceMark& mark, bool sync) {
  const std::string line = SequenceRecordLine(mark);
  if (::pwrite(record_fd_, line.data(), line.size(), 0) != static_cast<ssize_t>(line.size())) {
    return IoError("annotation sequence record " + record_path_ + ": write: " + Errno());
  }
  struct stat st {};
  if (::fstat(record_fd_, &st) == 0 && st.st_size != static_cast<off_t>(line.size()) &&
      ::ftruncate(record_fd_, static_cast<off_t>(line.size())) != 0) {
    return IoError("annotation sequence record " + record_path_ + ": truncate: " + Errno());
  }
  if (sync && ::fdatasync(record_fd_) != 0) {
    return IoError("annotation sequence record " + record_path_ + ": fdatasync: " + Errno());
  }
  return OkStatus();
}

}  // namespace sandtable::coordinator
