#include "common/io/json_reader.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include "common/base/file_io.h"

namespace sandtable::io {

using nlohmann::json;

std::string JoinField(std::string_view where, std::string_view key) {
  std::string out(where);
  if (out.empty()) return std::string(key);
  if (out.back() == ':') return out + " " + std::string(key);
  if (out.back() == ' ') return out + std::string(key);
  return out + "." + std::string(key);
}

std::string JoinIndex(std::string_view where, size_t index) {
  return std::string(where) + "[" + std::to_string(index) + "]";
}

ObjectReader::ObjectReader(const json& object, std::string where)
    : object_(object), where_(std::move(where)) {}

Status ObjectReader::Begin() const {
  if (!object_.is_object()) return ParseError(where_ + " must be a JSON object");
  return OkStatus();
}

bool ObjectReader::Has(std::string_view key) const {
  return object_.is_object() && object_.contains(key);
}

const json* ObjectReader::Find(std::string_view key) {
  used_.insert(std::string(key));
  if (!object_.is_object()) return nullptr;
  auto it = object_.find(key);
  return it == object_.end() ? nullptr : &*it;
}

Status ObjectReader::Missing(std::string_view key) const {
  return ParseError(Field(key) + " is missing");
}

namespace {

Expected<double> FiniteNumber(const json& value, const std::string& field) {
  if (!value.is_number()) return ParseError(field + " must be a number");
  const double x = value.get<double>();
  if (!std::isfinite(x)) return InvalidArgumentError(field + " is not finite");
  return x;
}

}  // namespace

Status ObjectReader::Number(std::string_view key, double* out, Presence presence) {
  const json* value = Find(key);
  if (value == nullptr) return presence == Presence::kRequired ? Missing(key) : OkStatus();
  Expected<double> x = FiniteNumber(*value, Field(key));
  if (!x.ok()) return x.status();
  *out = *x;
  return OkStatus();
}

Status ObjectReader::Integer(std::string_view key, int64_t min, int64_t max, int64_t* out,
                             Presence presence) {
  const json* value = Find(key);
  if (value == nullptr) return presence == Presence::kRequired ? Missing(key) : OkStatus();
  if (!value->is_number_integer()) return ParseError(Field(key) + " must be an integer");
  if (value->is_number_unsigned() && value->get<uint64_t>() > static_cast<uint64_t>(INT64_MAX)) {
    return InvalidArgumentError(Field(key) + " = " + value->dump() + " is out of range");
  }
  const int64_t x = value->get<int64_t>();
  if (x < min || x > max) {
    return InvalidArgumentError(Field(key) + " = " + std::to_string(x) + " must be in [" +
                                std::to_string(min) + ", " + std::to_string(max) + "]");
  }
  *out = x;
  return OkStatus();
}

Status ObjectReader::Int(std::string_view key, int min, int max, int* out, Presence presence) {
  int64_t x = 0;
  if (!Has(key) && presence == Presence::kOptional) {
    used_.insert(std::string(key));
    return OkStatus();
  }
  ST_RETURN_IF_ERROR(Integer(key, min, max, &x, presence));
  *out = static_cast<int>(x);
  return OkStatus();
}

Status ObjectReader::String(std::string_view key, std::string* out, Presence presence) {
  const json* value = Find(key);
  if (value == nullptr) return presence == Presence::kRequired ? Missing(key) : OkStatus();
  if (!value->is_string()) return ParseError(Field(key) + " must be a string");
  *out = value->get<std::string>();
  return OkStatus();
}

Status ObjectReader::Numbers(std::string_view key, std::span<double> out, Presence presence) {
  const json* value = Find(key);
  if (value == nullptr) return presence == Presence::kRequired ? Missing(key) : OkStatus();
  const std::string field = Field(key);
  if (!value->is_array() || value->size() != out.size()) {
    return ParseError(field + " must be an array of " + std::to_string(out.size()) + " numbers");
  }
  for (size_t i = 0; i < out.size(); ++i) {
    Expected<double> x = FiniteNumber((*value)[i], JoinIndex(field, i));
    if (!x.ok()) return x.status();
    out[i] = *x;
  }
  return OkStatus();
}

Status ObjectReader::Matrix(std::string_view key, int rows, int cols, std::span<double> out,
                            Presence presence) {
  ST_CHECK(out.size() == static_cast<size_t>(rows * cols)) << "Matrix: out has the wrong size";
  const json* value = Find(key);
  if (value == nullptr) return presence == Presence::kRequired ? Missing(key) : OkStatus();
  const std::string field = Field(key);
  const std::string shape = std::to_string(rows) + "x" + std::to_string(cols);
  if (!value->is_array() || value->size() != static_cast<size_t>(rows)) {
    return ParseError(field + " must be a " + shape + " array of rows");
  }
  for (int r = 0; r < rows; ++r) {
    const json& row = (*value)[r];
    const std::string row_field = JoinIndex(field, r);
    if (!row.is_array() || row.size() != static_cast<size_t>(cols)) {
      return ParseError(row_field + " must be an array of " + std::to_string(cols) + " numbers");
    }
    for (int c = 0; c < cols; ++c) {
      Expected<double> x = FiniteNumber(row[c], JoinIndex(row_field, c));
      if (!x.ok()) return x.status();
      out[r * cols + c] = *x;
    }
  }
  return OkStatus();
}

Status ObjectReader::Strings(std::string_view key, std::vector<std::string>* out,
                             Presence presence) {
  const json* value = Find(key);
  if (value == nullptr) return presence == Presence::kRequired ? Missing(key) : OkStatus();
  const std::string field = Field(key);
  if (!value->is_array()) return ParseError(field + " must be an array of strings");
  std::vector<std::string> strings;
  for (size_t i = 0; i < value->size(); ++i) {
    if (!(*value)[i].is_string()) return ParseError(JoinIndex(field, i) + " must be a string");
    strings.push_back((*value)[i].get<std::string>());
  }
  *out = std::move(strings);
  return OkStatus();
}

Expected<ObjectReader> ObjectReader::Object(std::string_view key) {
  const json* value = Find(key);
  if (value == nullptr) return Missing(key);
  ObjectReader child(*value, Field(key));
  ST_RETURN_IF_ERROR(child.Begin());
  return child;
}

Status ObjectReader::End() const {
  if (!object_.is_object()) return OkStatus();
  for (auto it = object_.begin(); it != object_.end(); ++it) {
    if (!used_.count(it.key())) return ParseError(where_ + " has unknown key '" + it.key() + "'");
  }
  return OkStatus();
}

Expected<int> ReadFormatVersion(ObjectReader* root, std::string_view format, int min_version,
                                int max_version) {
  std::string name;
  ST_RETURN_IF_ERROR(root->String("format", &name));
  if (name != format) {
    return ParseError(root->Field("format") + " = \"" + name + "\" must be \"" +
                      std::string(format) + "\"");
  }
  const json* version = root->Find("version");
  if (version == nullptr) return root->Missing("version");
  const std::string supported =
      min_version == max_version
          ? std::to_string(max_version)
          : "in [" + std::to_string(min_version) + ", " + std::to_string(max_version) + "]";
  if (!version->is_number_integer()) {
    return ParseError(root->Field("version") + " must be an integer (" + supported + ")");
  }
  const int64_t v = version->get<int64_t>();
  if (v < min_version || v > max_version) {
    return ParseError(root->Field("version") + " = " + std::to_string(v) + " is not supported (" +
                      std::string(format) + " " + supported + ")");
  }
  return static_cast<int>(v);
}

Expected<json> ParseJsonText(std::string_view text, std::string_view source) {
  try {
    return json::parse(text);
  } catch (const json::exception& e) {
    return ParseError(std::string(source) + ": not valid JSON (" + e.what() + ")");
  }
}

Expected<json> ReadJsonFile(const std::string& path) {
  Expected<std::string> text = ReadInputFile(path, kMaxJsonFileBytes, "kMaxJsonFileBytes");
  if (!text.ok()) return IoError(text.status().message());  // the message names the path
  if (text->find_first_not_of(" \t\r\n") == std::string::npos) {
    return ParseError(path + ": empty file, JSON is expected");
  }
  return ParseJsonText(*text, path);
}

Status WriteTextFile(const std::string& text, const std::string& path) {
  return WriteFileAtomically(path, text);
}

Status WriteJsonFile(const json& value, const std::string& path) {
  // Invalid UTF-8 in a string (a user-given name) is replaced, not thrown.
  return WriteTextFile(value.dump(2, ' ', false, json::error_handler_t::replace) + "\n", path);
}

}  // namespace sandtable::io
