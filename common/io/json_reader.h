// A small reader for untrusted JSON files: reads one object field by field, remembers where it
// is in the file, and names that place in every error. The file counterpart of the checks in
// proto/convert.h; json_codec.h builds the Rigid3d and CameraModel codecs on it.
//
// Paths: a reader is made for one JSON object with `where`, the path of that object as a
// message shows it: "unit-3.json: projector" (file, colon, dotted field path) or
// "site.units[1].camera". Fields are joined with '.', array elements with [i]:
//   JoinField("unit-3.json: projector", "fx_px") == "unit-3.json: projector.fx_px"
//   JoinField("unit-3.json:", "camera")          == "unit-3.json: camera"
// Errors (never exceptions, never aborts):
//   PARSE_ERROR       "<field> is missing", "<field> must be a number", "<where> has unknown
//                      key 'fx'", malformed JSON text ("unit.json: not valid JSON ...")
//   INVALID_ARGUMENT  a value of the right type out of its range: "<field> = 0 must be in
//                      [1, 65536]", "<field> is not finite"
//   IO_ERROR          a file that cannot be opened, read or written (naming the path)
#pragma once

#include <cstdint>
#include <set>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/base/status.h"

namespace sandtable::io {

std::string JoinField(std::string_view where, std::string_view key);
std::string JoinIndex(std::string_view where, size_t index);

enum class Presence { kRequired, kOptional };

class ObjectReader {
 public:
  // `object` must outlive the reader (and every reader made from it by Object()).
  ObjectReader(const nlohmann::json& object, std::string where);

  // PARSE_ERROR "<where> must be a JSON object" unless it is one. Call first.
  Status Begin() const;

  const std::string& where() const { return where_; }
  const nlohmann::json& value() const { return object_; }
  std::string Field(std::string_view key) const { return JoinField(where_, key); }
  bool Has(std::string_view key) const;

  // The member, or nullptr when absent (PARSE_ERROR through Missing() is the caller's choice).
  // Marks the key as read.
  const nlohmann::json* Find(std::string_view key);
  // Accepts the key without reading it (comments such as "convention").
  void Allow(std::string_view key) { used_.insert(std::string(key)); }

  // Each reads `key` into *out; an absent optional key leaves *out unchanged.
  Status Number(std::string_view key, double* out, Presence presence = Presence::kRequired);
  Status Integer(std::string_view key, int64_t min, int64_t max, int64_t* out,
                 Presence presence = Presence::kRequired);
  Status Int(std::string_view key, int min, int max, int* out,
             Presence presence = Presence::kRequired);
  Status String(std::string_view key, std::string* out, Presence presence = Presence::kRequired);
  // An array of exactly out.size() finite numbers.
  Status Numbers(std::string_view key, std::span<double> out,
                 Presence presence = Presence::kRequired);
  // An array of rows x cols finite numbers, as nested arrays (row-major into out).
  Status Matrix(std::string_view key, int rows, int cols, std::span<double> out,
                Presence presence = Presence::kRequired);
  Status Strings(std::string_view key, std::vector<std::string>* out,
                 Presence presence = Presence::kRequired);
  // A member object (required), already checked to be an object.
  Expected<ObjectReader> Object(std::string_view key);

  // PARSE_ERROR "<where> has unknown key 'x'" for the first key nothing read or allowed.
  Status End() const;

  Status Missing(std::string_view key) const;

 private:
  const nlohmann::json& object_;
  std::string where_;
  std::set<std::string, std::less<>> used_;
};

// Checks "format" and "version" of a file's root object: PARSE_ERROR naming the field when the
// format is not `format` or the version is outside [min_version, max_version]. Returns the
// version.
Expected<int> ReadFormatVersion(ObjectReader* root, std::string_view format, int min_version,
                                int max_version);

// JSON text -> value; PARSE_ERROR "<source>: not valid JSON (<parser's message>)".
Expected<nlohmann::json> ParseJsonText(std::string_view text, std::string_view source);
// Largest JSON file read (site, unit calibration, factory, true pose, table_from_tracker): 64 MiB.
inline constexpr uint64_t kMaxJsonFileBytes = uint64_t{64} << 20;
// Reads (through ReadInputFile: regular files only, at most kMaxJsonFileBytes) and parses a
// file; IO_ERROR naming the path when it is missing, not a regular file (a directory, FIFO,
// /dev/zero), over the limit or unreadable; PARSE_ERROR when empty or not JSON.
Expected<nlohmann::json> ReadJsonFile(const std::string& path);
// Writes the value pretty-printed (2 spaces) with a final newline through WriteFileAtomically
// (temporary file, fsync, rename: the previous file stays on failure); IO_ERROR naming the path.
Status WriteTextFile(const std::string& text, const std::string& path);
Status WriteJsonFile(const nlohmann::json& value, const std::string& path);

}  // namespace sandtable::io
