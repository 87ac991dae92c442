#include "common/io/mpcdi_zip.h"

#include <algorithm>
#include <cstring>
#include <set>

#include <minizip/ioapi.h>
#include <minizip/unzip.h>
#include <minizip/zip.h>

namespace sandtable::io {

namespace {

// A byte buffer seen by minizip as a file (ioapi.h's zlib_filefunc64_def). Reading uses `input`;
// writing appends to or overwrites `*output` at `position` (zip.c seeks back to patch headers).
struct MemoryFile {
  std::string_view input;
  std::string* output = nullptr;
  uint64_t position = 0;

  uint64_t size() const { return output != nullptr ? output->size() : input.size(); }
};

voidpf ZCALLBACK MemoryOpen(voidpf opaque, const void* /*filename*/, int /*mode*/) {
  return opaque;
}

uLong ZCALLBACK MemoryRead(voidpf /*opaque*/, voidpf stream, void* buffer, uLong size) {
  auto* file = static_cast<MemoryFile*>(stream);
  if (file->output != nullptr || file->position >= file->input.size()) return 0;
  const uint64_t n = std::min<uint64_t>(size, file->input.size() - file->position);
  std::memcpy(buffer, file->input.data() + file->position, n);
  file->position += n;
  return static_cast<uLong>(n);
}

uLong ZCALLBACK MemoryWrite(voidpf /*opaque*/, voidpf stream, const void* buffer, uLong size) {
  auto* file = static_cast<MemoryFile*>(stream);
  if (file->output == nullptr) return 0;
  std::string& out = *file->output;
  if (file->position > out.size()) out.resize(file->position, '\0');
  const uint64_t overlap = std::min<uint64_t>(size, out.size() - file->position);
  out.replace(file->position, overlap, static_cast<const char*>(buffer), size);
  file->position += size;
  return size;
}

ZPOS64_T ZCALLBACK MemoryTell(voidpf /*opaque*/, voidpf stream) {
  return static_cast<MemoryFile*>(stream)->position;
}

long ZCALLBACK MemorySeek(voidpf /*opaque*/, voidpf stream, ZPOS64_T offset, int origin) {
  auto* file = static_cast<MemoryFile*>(stream);
  uint64_t base = 0;
  switch (origin) {
    case ZLIB_FILEFUNC_SEEK_SET:
      base = 0;
      break;
    case ZLIB_FILEFUNC_SEEK_CUR:
      base = file->position;
      break;
    case ZLIB_FILEFUNC_SEEK_END:
      base = file->size();
      break;
    default:
      return -1;
  }
  if (offset > file->size() - std::min(base, file->size())) return -1;  // past the end
  file->position = base + offset;
  return 0;
}

int ZCALLBACK MemoryClose(voidpf /*opaque*/, voidpf /*stream*/) { return 0; }
int ZCALLBACK MemoryError(voidpf /*opaque*/, voidpf /*stream*/) { return 0; }

zlib_filefunc64_def MemoryFunctions(MemoryFile* file) {
  zlib_filefunc64_def functions{};
  functions.zopen64_file = MemoryOpen;
  functions.zread_file = MemoryRead;
  functions.zwrite_file = MemoryWrite;
  functions.ztell64_file = MemoryTell;
  functions.zseek64_file = MemorySeek;
  functions.zclose_file = MemoryClose;
  functions.zerror_file = MemoryError;
  functions.opaque = file;
  return functions;
}

bool IsPlainName(std::string_view name) {
  return !name.empty() && name != "." && name != ".." &&
         name.find_first_of(std::string_view("/\\\0", 3)) == std::string_view::npos;
}

// Closes the archive being read on every path out of DecodeZipArchive.
struct UnzipCloser {
  unzFile file;
  ~UnzipCloser() { unzClose(file); }
};

}  // namespace

bool LooksLikeZip(std::string_view bytes) {
  return bytes.size() >= 4 && bytes[0] == 'P' && bytes[1] == 'K' &&
         ((bytes[2] == 3 && bytes[3] == 4) || (bytes[2] == 5 && bytes[3] == 6));
}

Expected<std::string> EncodeZipArchive(const std::vector<ZipEntry>& entries) {
  std::set<std::string> names;
  for (const ZipEntry& entry : entries) {
    if (!IsPlainName(entry.name)) {
      return InvalidArgumentError("ZIP entry name \"" + entry.name + "\" is not a plain file name");
    }
    if (!names.insert(entry.name).second) {
      return InvalidArgumentError("ZIP entry \"" + entry.name + "\" given twice");
    }
  }
  std::string archive;
  MemoryFile file;
  file.output = &archive;
  zlib_filefunc64_def functions = MemoryFunctions(&file);
  zipFile zip = zipOpen2_64("memory", APPEND_STATUS_CREATE, nullptr, &functions);
  if (zip == nullptr) return InternalError("minizip: zipOpen2_64 failed");
  for (const ZipEntry& entry : entries) {
    // A fixed timestamp (1980-01-01 00:00, the first DOS date) and no attributes: the same
    // entries give the same bytes.
    zip_fileinfo info{};
    info.tmz_date.tm_mday = 1;
    const int zip64 = entry.bytes.size() >= 0xffffffffu ? 1 : 0;
    int rc = zipOpenNewFileInZip64(zip, entry.name.c_str(), &info, nullptr, 0, nullptr, 0, nullptr,
                                   Z_DEFLATED, Z_DEFAULT_COMPRESSION, zip64);
    // zipWriteInFileInZip takes an unsigned length: write in chunks.
    constexpr size_t kChunk = size_t{1} << 30;
    for (size_t at = 0; rc == ZIP_OK && at < entry.bytes.size(); at += kChunk) {
      const size_t n = std::min(kChunk, entry.bytes.size() - at);
      rc = zipWriteInFileInZip(zip, entry.bytes.data() + at, static_cast<unsigned>(n));
    }
    if (rc == ZIP_OK) rc = zipCloseFileInZip(zip);
    if (rc != ZIP_OK) {
      zipClose(zip, nullptr);
      return InternalError("minizip: writing entry \"" + entry.name + "\" failed (" +
                           std::to_string(rc) + ")");
    }
  }
  if (zipClose(zip, nullptr) != ZIP_OK) return InternalError("minizip: zipClose failed");
  return archive;
}

Expected<std::vector<ZipEntry>> DecodeZipArchive(std::string_view bytes, std::string_view source,
                                                 const ZipReadLimits& limits) {
  const std::string where(source);
  MemoryFile file;
  file.input = bytes;
  zlib_filefunc64_def functions = MemoryFunctions(&file);
  unzFile unzip = unzOpen2_64("memory", &functions);
  if (unzip == nullptr) {
    return ParseError(where + ": not a readable ZIP archive (no end of central directory: " +
                      "truncated or damaged?)");
  }
  UnzipCloser closer{unzip};
  unz_global_info64 global{};
  if (unzGetGlobalInfo64(unzip, &global) != UNZ_OK) {
    return ParseError(where + ": ZIP central directory unreadable");
  }
  if (global.number_entry > static_cast<uint64_t>(limits.max_entries)) {
    return InvalidArgumentError(where + ": ZIP archive holds " +
                                std::to_string(global.number_entry) + " entries, over the limit " +
                                std::to_string(limits.max_entries));
  }
  std::vector<ZipEntry> entries;
  std::set<std::string> names;
  uint64_t total_bytes = 0;
  for (int rc = unzGoToFirstFile(unzip); rc != UNZ_END_OF_LIST_OF_FILE;
       rc = unzGoToNextFile(unzip)) {
    if (rc != UNZ_OK) {
      return ParseError(where + ": ZIP central directory damaged after entry " +
                        std::to_string(entries.size()));
    }
    unz_file_info64 info{};
    char name_buffer[1024] = {};
    if (unzGetCurrentFileInfo64(unzip, &info, name_buffer, sizeof(name_buffer) - 1, nullptr, 0,
                                nullptr, 0) != UNZ_OK ||
        info.size_filename >= sizeof(name_buffer)) {
      return ParseError(where + ": ZIP entry " + std::to_string(entries.size()) +
                        " has an unreadable or over-long name");
    }
    ZipEntry entry;
    entry.name.assign(name_buffer, info.size_filename);
    const std::string what = where + ": ZIP entry \"" + entry.name + "\"";
    if (!IsPlainName(entry.name)) {
      return InvalidArgumentError(what + " is not a plain file name (MPCDI archives hold no " +
                                  "folders)");
    }
    if (!names.insert(entry.name).second) return ParseError(what + " appears twice");
    if ((info.flag & 1u) != 0) return ParseError(what + " is encrypted");
    if (info.compression_method != 0 && info.compression_method != Z_DEFLATED) {
      return ParseError(what + " uses compression method " +
                        std::to_string(info.compression_method) + " (stored or deflate only)");
    }
    if (info.uncompressed_size > limits.max_entry_bytes) {
      return InvalidArgumentError(what + " declares " + std::to_string(info.uncompressed_size) +
                                  " bytes, over the per-entry limit " +
                                  std::to_string(limits.max_entry_bytes));
    }
    total_bytes += info.uncompressed_size;
    if (total_bytes > limits.max_total_bytes) {
      return InvalidArgumentError(where + ": ZIP entries declare more than " +
                                  std::to_string(limits.max_total_bytes) +
                                  " bytes in all, over the limit");
    }
    if (unzOpenCurrentFile(unzip) != UNZ_OK) return ParseError(what + ": cannot open");
    // Read one byte more than declared, so that an entry longer than its header says is caught.
    entry.bytes.resize(info.uncompressed_size + 1);
    uint64_t got = 0;
    while (got < entry.bytes.size()) {
      const auto want =
          static_cast<unsigned>(std::min<uint64_t>(entry.bytes.size() - got, 1u << 30));
      const int n = unzReadCurrentFile(unzip, entry.bytes.data() + got, want);
      if (n < 0) {
        unzCloseCurrentFile(unzip);
        return ParseError(what + ": damaged data, inflate failed (minizip " + std::to_string(n) +
                          ")");
      }
      if (n == 0) break;
      got += static_cast<uint64_t>(n);
    }
    const int close_rc = unzCloseCurrentFile(unzip);
    if (got != info.uncompressed_size) {
      return ParseError(what + ": inflates to " +
                        (got > info.uncompressed_size ? "more" : "fewer") + " bytes than the " +
                        std::to_string(info.uncompressed_size) + " declared");
    }
    if (close_rc == UNZ_CRCERROR) return ParseError(what + ": CRC mismatch");
    if (close_rc != UNZ_OK)
      return ParseError(what + ": damaged (minizip " + std::to_string(close_rc) + ")");
    entry.bytes.resize(got);
    entries.push_back(std::move(entry));
  }
  return entries;
}

}  // namespace sandtable::io
