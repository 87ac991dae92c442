#include "common/cli/config_file.h"

#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

namespace sandtable::cli {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A file being read: its path (for messages), its folder (for relative paths), the flags so far.
class Reader {
 public:
  Reader(fs::path path, json doc) : path_(std::move(path)), doc_(std::move(doc)) {}

  Status Error(const std::string& key, const std::string& why) const {
    return InvalidArgumentError(path_.string() + ": " + (key.empty() ? "" : "\"" + key + "\": ") +
                                why);
  }
  const json& doc() const { return doc_; }
  std::vector<std::string>& flags() { return flags_; }

  // The header: the format named, a version this build reads.
  Expected<int> Header(const char* format, int newest) const {
    if (!doc_.is_object()) return Error("", "not a JSON object");
    if (!doc_.contains("format") || doc_["format"] != format) {
      return Error("format", std::string("must be \"") + format + "\"");
    }
    if (!doc_.contains("version") || !doc_["version"].is_number_integer()) {
      return Error("version", "must be an integer");
    }
    const int version = doc_["version"].get<int>();
    if (version < 1) return Error("version", "must be >= 1");
    if (version > newest) {
      return Error("version", std::to_string(version) +
                                  " was written by a newer sandtable (this build reads up to " +
                                  std::to_string(newest) + ")");
    }
    return version;
  }

  // Every key of `object` (at `where`) must be one of `known`.
  Status OnlyKnown(const json& object, const std::string& where,
                   const std::set<std::string>& known) const {
    for (const auto& [key, value] : object.items()) {
      if (!known.count(key)) {
        std::string list;
        for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
        return Error(where + key, "unknown key (known: " + list + ")");
      }
    }
    return OkStatus();
  }

  Expected<std::string> String(const json& object, const std::string& key,
                               const std::string& where) const {
    const json& v = object.at(key);
    if (!v.is_string() || v.get<std::string>().empty()) {
      return Error(where + key, "must be a non-empty string");
    }
    return v.get<std::string>();
  }
  Expected<long long> Integer(const json& object, const std::string& key,
                              const std::string& where) const {
    const json& v = object.at(key);
    if (!v.is_number_integer()) return Error(where + key, "must be an integer");
    return v.get<long long>();
  }
  // A path, relative ones taken from the file's folder.
  Expected<std::string> Path(const json& object, const std::string& key,
                             const std::string& where) const {
    Expected<std::string> text = String(object, key, where);
    if (!text.ok()) return text.status();
    const fs::path p(*text);
    return p.is_absolute() ? p.string() : (path_.parent_path() / p).lexically_normal().string();
  }

  void Add(const std::string& flag, const std::string& value) {
    flags_.push_back("--" + flag);
    flags_.push_back(value);
  }

  // A section of flags by name ("render-max-fps": 30): strings and numbers as their values,
  // true as the bare flag, false left out.
  Status FlagSection(const json& object, const std::string& where) {
    if (!object.is_object()) return Error(where, "must be an object of flags by name");
    for (const auto& [name, value] : object.items()) {
      if (name.empty() || name.front() == '-') {
        return Error(where + "." + name, "a flag's name without the leading --");
      }
      if (name == "site-config" || name == "unit-config") {
        return Error(where + "." + name, "a configuration file cannot name another");
      }
      if (value.is_boolean()) {
        if (value.get<bool>()) flags_.push_back("--" + name);
      } else if (value.is_string()) {
        Add(name, value.get<std::string>());
      } else if (value.is_number_integer()) {
        Add(name, std::to_string(value.get<long long>()));
      } else if (value.is_number()) {
        std::ostringstream text;
        text.precision(17);
        text << value.get<double>();
        Add(name, text.str());
      } else {
        return Error(where + "." + name, "must be a string, a number or a boolean");
      }
    }
    return OkStatus();
  }

 private:
  fs::path path_;
  json doc_;
  std::vector<std::string> flags_;
};

Expected<Reader> Open(const fs::path& path) {
  std::ifstream in(path);
  if (!in) return NotFoundError(path.string() + ": cannot be read");
  json doc = json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded()) return InvalidArgumentError(path.string() + ": not JSON");
  return Reader(path, std::move(doc));
}

#define ST_ASSIGN(var, expr)                    \
  auto var##_or = (expr);                       \
  if (!var##_or.ok()) return var##_or.status(); \
  const auto var = *var##_or

Status ReadCoordinator(Reader& r, ConfigProgram program) {
  const json& c = r.doc()["coordinator"];
  if (!c.is_object()) return r.Error("coordinator", "must be an object");
  ST_RETURN_IF_ERROR(
      r.OnlyKnown(c, "coordinator.", {"host", "requests_port", "events_port", "listen"}));
  for (const char* key : {"requests_port", "events_port"}) {
    if (!c.contains(key)) return r.Error(std::string("coordinator.") + key, "missing");
  }
  // Without a host the nodes find the coordinator by its beacon; the ports are where it listens.
  const bool discovered = r.doc().contains("discovery");
  if (!c.contains("host") && !discovered) {
    return r.Error("coordinator.host",
                   "missing (or add a discovery section: the nodes then find the coordinator by "
                   "its beacon)");
  }
  std::string host;
  if (c.contains("host")) {
    ST_ASSIGN(given_host, r.String(c, "host", "coordinator."));
    host = given_host;
  }
  ST_ASSIGN(requests, r.Integer(c, "requests_port", "coordinator."));
  ST_ASSIGN(events, r.Integer(c, "events_port", "coordinator."));
  for (long long port : {requests, events}) {
    if (port < 1 || port > 65535) return r.Error("coordinator", "ports must be in 1..65535");
  }
  if (requests == events) return r.Error("coordinator", "the two ports must differ");
  if (program == ConfigProgram::kNode) {
    if (!host.empty()) {
      r.Add("coordinator", "tcp://" + host + ":" + std::to_string(requests) + ",tcp://" + host +
                               ":" + std::to_string(events));
    }
    return OkStatus();
  }
  std::string listen = "*";
  if (c.contains("listen")) {
    ST_ASSIGN(given, r.String(c, "listen", "coordinator."));
    listen = given;
  }
  r.Add("requests", "tcp://" + listen + ":" + std::to_string(requests));
  r.Add("events", "tcp://" + listen + ":" + std::to_string(events));
  return OkStatus();
}

// Site file, version 1 (docs/config-file.md).
Status ReadSite(Reader& r, ConfigProgram program) {
  const json& d = r.doc();
  ST_RETURN_IF_ERROR(r.OnlyKnown(
      d, "",
      {"format", "version", "coordinator", "discovery", "curve_keys", "insecure", "status",
       "heartbeat_ms", "misses", "model", "expect_units", "node_flags", "coordinator_flags"}));
  const bool node = program == ConfigProgram::kNode;
  if (d.contains("coordinator")) ST_RETURN_IF_ERROR(ReadCoordinator(r, program));
  // A site that accepts new units: a node's key file may not exist yet (it asks for it).
  const bool enrolling = d.contains("discovery") && d["discovery"].is_object() &&
                         d["discovery"].contains("enroll_port");
  if (d.contains("curve_keys")) {
    ST_ASSIGN(keys, r.Path(d, "curve_keys", ""));
    r.Add(node && enrolling ? "enroll" : "curve-keys", keys);
  }
  if (d.contains("discovery")) {
    const json& disc = d["discovery"];
    if (!disc.is_object()) return r.Error("discovery", "must be an object");
    ST_RETURN_IF_ERROR(r.OnlyKnown(disc, "discovery.", {"port", "site", "enroll_port"}));
    if (enrolling) {
      ST_ASSIGN(enroll, r.Integer(disc, "enroll_port", "discovery."));
      if (enroll < 1 || enroll > 65535)
        return r.Error("discovery.enroll_port", "must be in 1..65535");
      if (!d.contains("curve_keys")) {
        return r.Error("discovery.enroll_port", "needs curve_keys (the key a unit is handed)");
      }
      if (!node) {
        std::string listen = "*";
        if (d.contains("coordinator") && d["coordinator"].is_object() &&
            d["coordinator"].contains("listen")) {
          ST_ASSIGN(given, r.String(d["coordinator"], "listen", "coordinator."));
          listen = given;
        }
        r.Add("enroll", "tcp://" + listen + ":" + std::to_string(enroll));
      }
    }
    std::string port = "5670";
    if (disc.contains("port")) {
      ST_ASSIGN(p, r.Integer(disc, "port", "discovery."));
      if (p < 1 || p > 65535) return r.Error("discovery.port", "must be in 1..65535");
      port = std::to_string(p);
    }
    if (node) {
      // An explicit coordinator address stays the way in; discovery is for a site without one.
      const bool has_host = d.contains("coordinator") && d["coordinator"].is_object() &&
                            d["coordinator"].contains("host");
      if (!has_host) r.Add("coordinator", "discover");
      r.Add("discovery-port", port);
    } else {
      r.Add("beacon", port);
    }
    if (disc.contains("site")) {
      ST_ASSIGN(site, r.String(disc, "site", "discovery."));
      r.Add("site-name", site);
    }
  }
  if (d.contains("insecure")) {
    if (!d["insecure"].is_boolean()) return r.Error("insecure", "must be true or false");
    if (d["insecure"].get<bool>()) r.flags().push_back("--insecure");
  }
  if (d.contains("heartbeat_ms")) {
    ST_ASSIGN(ms, r.Integer(d, "heartbeat_ms", ""));
    r.Add("heartbeat-ms", std::to_string(ms));
  }
  if (d.contains("model")) {
    ST_ASSIGN(model, r.Path(d, "model", ""));
    r.Add(node ? "model" : "scene", model);
  }
  if (d.contains("status")) {
    const json& s = d["status"];
    if (!s.is_object()) return r.Error("status", "must be an object");
    ST_RETURN_IF_ERROR(r.OnlyKnown(s, "status.", {"listen", "token_file"}));
    if (!node && s.contains("listen")) {
      ST_ASSIGN(listen, r.String(s, "listen", "status."));
      r.Add("status", listen);
    }
    if (!node && s.contains("token_file")) {
      ST_ASSIGN(token, r.Path(s, "token_file", "status."));
      r.Add("status-token-file", token);
    }
  }
  if (!node && d.contains("misses")) {
    ST_ASSIGN(misses, r.Integer(d, "misses", ""));
    r.Add("misses", std::to_string(misses));
  }
  if (node && d.contains("expect_units")) {
    ST_ASSIGN(units, r.Integer(d, "expect_units", ""));
    r.Add("expect-units", std::to_string(units));
  }
  const char* own = node ? "node_flags" : "coordinator_flags";
  if (d.contains(own)) ST_RETURN_IF_ERROR(r.FlagSection(d[own], own));
  return OkStatus();
}

// Unit file, version 1.
Status ReadUnit(Reader& r) {
  const json& d = r.doc();
  ST_RETURN_IF_ERROR(
      r.OnlyKnown(d, "",
                  {"format", "version", "id", "factory", "projector", "camera", "bind", "advertise",
                   "export_dir", "saved_calibration", "node_flags"}));
  if (d.contains("id")) {
    ST_ASSIGN(id, r.Integer(d, "id", ""));
    r.Add("id", std::to_string(id));
  }
  for (const auto& [key, flag] : std::map<std::string, std::string>{{"projector", "projector"},
                                                                    {"camera", "camera"},
                                                                    {"bind", "bind"},
                                                                    {"advertise", "advertise"}}) {
    if (!d.contains(key)) continue;
    ST_ASSIGN(value, r.String(d, key, ""));
    r.Add(flag, value);
  }
  for (const auto& [key, flag] :
       std::map<std::string, std::string>{{"factory", "factory"},
                                          {"export_dir", "export-dir"},
                                          {"saved_calibration", "saved-calibration"}}) {
    if (!d.contains(key)) continue;
    ST_ASSIGN(value, r.Path(d, key, ""));
    r.Add(flag, value);
  }
  if (d.contains("node_flags")) ST_RETURN_IF_ERROR(r.FlagSection(d["node_flags"], "node_flags"));
  return OkStatus();
}

#undef ST_ASSIGN

// The names ("--name") the arguments give, with or without "=value".
std::set<std::string> GivenNames(const std::vector<std::string>& args) {
  std::set<std::string> names;
  for (const std::string& a : args) {
    if (a.rfind("--", 0) != 0 || a.size() == 2) continue;
    names.insert(a.substr(0, a.find('=')));
  }
  return names;
}

// The value of `flag` in the arguments ("--flag V" or "--flag=V"), empty when absent.
std::string ValueOf(const std::vector<std::string>& args, const std::string& flag) {
  for (size_t i = 0; i < args.size(); ++i) {
    if (args[i] == flag && i + 1 < args.size()) return args[i + 1];
    if (args[i].rfind(flag + "=", 0) == 0) return args[i].substr(flag.size() + 1);
  }
  return {};
}

}  // namespace

Expected<std::vector<std::string>> SiteConfigFlags(const fs::path& path, ConfigProgram program) {
  Expected<Reader> r = Open(path);
  if (!r.ok()) return r.status();
  Expected<int> version = r->Header(kSiteConfigFormat, kSiteConfigVersion);
  if (!version.ok()) return version.status();
  ST_RETURN_IF_ERROR(ReadSite(*r, program));  // version 1 is the first: no migration yet
  return std::move(r->flags());
}

Expected<std::vector<std::string>> UnitConfigFlags(const fs::path& path) {
  Expected<Reader> r = Open(path);
  if (!r.ok()) return r.status();
  Expected<int> version = r->Header(kUnitConfigFormat, kUnitConfigVersion);
  if (!version.ok()) return version.status();
  ST_RETURN_IF_ERROR(ReadUnit(*r));
  return std::move(r->flags());
}

Expected<std::vector<std::string>> ExpandConfigFiles(const std::vector<std::string>& args,
                                                     ConfigProgram program) {
  std::vector<std::string> from_files;
  const std::string site = ValueOf(args, "--site-config");
  if (!site.empty()) {
    Expected<std::vector<std::string>> flags = SiteConfigFlags(site, program);
    if (!flags.ok()) return flags.status();
    from_files = std::move(*flags);
  }
  const std::string unit = ValueOf(args, "--unit-config");
  if (!unit.empty()) {
    if (program != ConfigProgram::kNode) {
      return InvalidArgumentError("--unit-config: only sandtable-node reads a unit's file");
    }
    Expected<std::vector<std::string>> flags = UnitConfigFlags(unit);
    if (!flags.ok()) return flags.status();
    from_files.insert(from_files.end(), flags->begin(), flags->end());
  }
  if (from_files.empty()) return args;
  // A flag given by the command line, or by the unit's file over the site's, wins: the file's
  // occurrence is left out (the later of the two files is kept).
  const std::set<std::string> given = GivenNames(args);
  std::vector<std::string> out;
  std::set<std::string> taken;
  for (size_t i = from_files.size(); i-- > 0;) {
    const std::string& word = from_files[i];
    if (word.rfind("--", 0) != 0) continue;
    const bool has_value = i + 1 < from_files.size() && from_files[i + 1].rfind("--", 0) != 0;
    if (given.count(word) || taken.count(word)) continue;
    taken.insert(word);
    if (has_value) out.insert(out.begin(), from_files[i + 1]);
    out.insert(out.begin(), word);
  }
  out.insert(out.end(), args.begin(), args.end());
  return out;
}

void AddConfigFileFlags(CLI::App& app, ConfigProgram program) {
  app.add_option("--site-config",
                 "the site's configuration file (docs/config-file.md); flags "
                 "given here win over it")
      ->check(CLI::ExistingFile);
  if (program == ConfigProgram::kNode) {
    app.add_option("--unit-config", "this unit's configuration file (docs/config-file.md)")
        ->check(CLI::ExistingFile);
  }
}

}  // namespace sandtable::cli
