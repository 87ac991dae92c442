// The one way a program reads an input file and writes an output file.
//
// Reading: every file named on a command line, in a site/scene/session or by another file goes
// through ReadInputFile. It refuses, with a message naming the path, anything that is not a
// regular file (a directory, FIFO, character device such as /dev/zero, socket) before reading a
// byte, opens non-blocking (a FIFO swapped in after the check cannot hang the reader) and stops
// reading past `max_bytes` (the caller's documented limit, named in the message through
// `limit_name`, e.g. "kMaxSiteFileBytes"). Codes: NOT_FOUND (missing), IO_ERROR (not regular,
// unreadable, over the limit).
//
// Writing: every output (export, report, scene, image, calibration) goes through
// WriteFileAtomically: the bytes go to a temporary file in the same folder, every write is
// checked, the file is fsynced, renamed over the target and the folder fsynced. On any failure
// (full disk, no permission) the temporary file is removed, the previous file at `path` stays as
// it was, and IO_ERROR names the path and the cause. A reader never sees a half-written file.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "common/base/status.h"

namespace sandtable {

// Default bound for small text inputs (site, unit, pose, key files): 64 MiB.
inline constexpr uint64_t kMaxTextInputBytes = uint64_t{64} << 20;

// Reads the whole regular file at `path`, at most `max_bytes` bytes.
Expected<std::string> ReadInputFile(const std::filesystem::path& path, uint64_t max_bytes,
                                    std::string_view limit_name = "kMaxTextInputBytes");

// Checks that `path` names a regular file of at most `max_bytes` without reading it (for inputs
// a library opens itself, e.g. SQLite or cv::VideoCapture).
Status CheckInputFile(const std::filesystem::path& path, uint64_t max_bytes,
                      std::string_view limit_name = "kMaxTextInputBytes");

// Replaces the file at `path` with `bytes`, all or nothing (see above). `mode` is the
// permission of the new file (0600 for secrets); the folder must exist.
Status WriteFileAtomically(const std::filesystem::path& path, std::string_view bytes,
                           unsigned mode = 0644);

}  // namespace sandtable
