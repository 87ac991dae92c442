// Command-line flags of sandtable-world: `--name value`, `--name=value`, `-o value`, switches.
//
// A FlagSpec lists the accepted flags; anything else, a missing value, a repeated single-value
// flag, or a missing required flag is an INVALID_ARGUMENT naming the flag, which the program
// reports as a usage error (exit code 2).
#pragma once

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "common/base/status.h"

namespace sandtable::sim {

struct FlagSpec {
  std::set<std::string> values;    // --name VALUE, at most once
  std::set<std::string> repeated;  // --name VALUE, any number of times
  std::set<std::string> switches;  // --name
  std::set<std::string> required;  // subset of `values`
};

class Flags {
 public:
  // `args` excludes the program and subcommand names.
  static Expected<Flags> Parse(const std::vector<std::string>& args, const FlagSpec& spec);

  bool Has(const std::string& name) const { return values_.count(name) || switches_.count(name); }
  // The value of a single-value flag, or `fallback`.
  std::string Get(const std::string& name, const std::string& fallback = "") const;
  std::vector<std::string> GetAll(const std::string& name) const;
  // Parsed integer flags: INVALID_ARGUMENT naming the flag when not an integer in [lo, hi].
  Expected<int64_t> GetInt(const std::string& name, int64_t fallback, int64_t lo, int64_t hi) const;
  Expected<double> GetDouble(const std::string& name, double fallback) const;

 private:
  std::map<std::string, std::vector<std::string>> values_;
  std::set<std::string> switches_;
};

}  // namespace sandtable::sim
