// Site and unit configuration files (docs/config-file.md): JSON with "format" and "version",
// read into the flags they stand for, so that a file and a command line go through one parser
// (the program's own CLI11 flags, their checks and messages) and a flag given on the command
// line wins over the file's.
//
//   sandtable-coordinator --site-config site.json
//   sandtable-node --site-config site.json --unit-config unit-3.json [--flag value ...]
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "common/base/status.h"

namespace CLI {
class App;
}

namespace sandtable::cli {

enum class ConfigProgram { kNode, kCoordinator };

inline constexpr char kSiteConfigFormat[] = "sandtable.site_config";
inline constexpr char kUnitConfigFormat[] = "sandtable.unit_config";
// The newest versions this build reads (and every older one).
inline constexpr int kSiteConfigVersion = 1;
inline constexpr int kUnitConfigVersion = 1;

// The flags (command-line words, "--name" then its value) a site file sets for `program`;
// relative paths in it are taken from `path`'s folder. INVALID_ARGUMENT naming the file and the
// key for anything it does not hold as documented (an unknown key, a value of the wrong type, a
// version newer than this build's); NOT_FOUND when it cannot be read.
Expected<std::vector<std::string>> SiteConfigFlags(const std::filesystem::path& path,
                                                   ConfigProgram program);
// The same for a unit's file (the node only).
Expected<std::vector<std::string>> UnitConfigFlags(const std::filesystem::path& path);

// A program's arguments (without the program's name) with the files named by --site-config and
// --unit-config (the node's) read: their flags first, less those the arguments give too (the
// command line wins), then the arguments as given (the file flags stay, so --help lists them).
Expected<std::vector<std::string>> ExpandConfigFiles(const std::vector<std::string>& args,
                                                     ConfigProgram program);

// Registers --site-config (and for the node --unit-config) on `app`.
void AddConfigFileFlags(CLI::App& app, ConfigProgram program);

}  // namespace sandtable::cli
