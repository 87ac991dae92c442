// The flags a CLI11 help text lists: the first column of its option lines ("  -o,--output TEXT
// ..." -> {"-o", "--output"}), so tests can compare --help against what a program registered.
#pragma once

#include <set>
#include <sstream>
#include <string>

namespace sandtable::testing {

inline std::set<std::string> FlagsInHelp(const std::string& help) {
  std::set<std::string> flags;
  std::istringstream lines(help);
  std::string line;
  while (std::getline(lines, line)) {
    const size_t start = line.find_first_not_of(' ');
    if (start == std::string::npos || start == 0 || line[start] != '-') continue;
    const std::string column = line.substr(start, line.find(' ', start) - start);
    std::istringstream names(column);
    std::string name;
    while (std::getline(names, name, ',')) {
      if (name.size() >= 2 && name[0] == '-') flags.insert(name);
    }
  }
  return flags;
}

}  // namespace sandtable::testing
