#include "common/cli/command_line.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace sandtable::cli {
namespace {

std::string ProgramName(const CLI::App& app) {
  // A subcommand's errors name the whole command ("sandtable-world serve").
  std::string name = app.get_name();
  for (const CLI::App* parent = app.get_parent(); parent != nullptr;
       parent = parent->get_parent()) {
    name = parent->get_name() + " " + name;
  }
  return name;
}

// The app the error is about: the deepest selected subcommand.
const CLI::App& Selected(const CLI::App& app) {
  const CLI::App* current = &app;
  while (true) {
    const std::vector<const CLI::App*> selected =
        current->get_subcommands([](const CLI::App* sub) { return sub->parsed(); });
    if (selected.empty()) return *current;
    current = selected.front();
  }
}

// Edit distance (insertions, deletions, substitutions) between two names.
size_t Distance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diagonal = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] != b[j - 1] ? 1 : 0)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

// The name of `names` closest to `given`, when it is close enough to be a typo (at most a third
// of its length, and at least 2, edits away: two swapped letters are two edits); empty otherwise.
std::string Closest(const std::string& given, const std::vector<std::string>& names) {
  std::string best;
  size_t best_distance = std::max<size_t>(2, given.size() / 3) + 1;
  for (const std::string& name : names) {
    const size_t d = Distance(given, name);
    if (d < best_distance) {
      best_distance = d;
      best = name;
    }
  }
  return best;
}

std::vector<std::string> SubcommandNames(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; })) {
    names.push_back(sub->get_name());
  }
  return names;
}

// What to add to an error about the command line `args`: the flag or subcommand the user
// probably meant, and the subcommands there are when one is missing.
std::string Hint(const CLI::App& app, const CLI::ParseError& e,
                 const std::vector<std::string>& args) {
  const CLI::App& selected = Selected(app);
  std::vector<std::string> flags;
  for (const CLI::App* a = &selected; a != nullptr; a = a->get_parent()) {
    for (const std::string& name : FlagNames(*a)) flags.push_back(name);
  }
  std::string hint;
  for (const std::string& arg : args) {
    if (arg.rfind("--", 0) != 0 || arg.size() < 3) continue;
    const std::string name = arg.substr(0, arg.find('='));
    if (std::find(flags.begin(), flags.end(), name) != flags.end()) continue;
    const std::string closest = Closest(name, flags);
    if (!closest.empty()) hint += "; did you mean " + closest + " (not " + name + ")?";
  }
  const std::vector<std::string> subcommands = SubcommandNames(selected);
  const std::string what = e.what();
  if (!subcommands.empty() && what.find("ubcommand") != std::string::npos) {
    std::string list;
    for (const std::string& name : subcommands) list += (list.empty() ? "" : ", ") + name;
    for (const std::string& arg : args) {
      if (arg.empty() || arg[0] == '-') continue;
      const std::string closest = Closest(arg, subcommands);
      hint += "; '" + arg + "' is not a subcommand" +
              (closest.empty() ? std::string() : " (did you mean " + closest + "?)");
      break;
    }
    hint += "; the subcommands are " + list;
  }
  return hint;
}

int Exit(const CLI::App& app, const CLI::ParseError& e, const std::vector<std::string>& args,
         std::ostream& out, std::ostream& err) {
  if (e.get_exit_code() == static_cast<int>(CLI::ExitCodes::Success)) {
    app.exit(e, out, err);  // --help: the selected (sub)command's help on `out`
    return kExitOk;
  }
  return UsageError(Selected(app), e.what() + Hint(app, e, args), err);
}

}  // namespace

void Configure(CLI::App& app) {
  app.option_defaults()->always_capture_default();
  app.set_help_flag("-h,--help", "Print this help message (every flag) and exit");
}

std::optional<int> Parse(CLI::App& app, int argc, const char* const* argv, std::ostream& out,
                         std::ostream& err) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return Exit(app, e, std::vector<std::string>(argv + std::min(argc, 1), argv + argc), out, err);
  }
  return std::nullopt;
}

std::optional<int> Parse(CLI::App& app, const std::vector<std::string>& args, std::ostream& out,
                         std::ostream& err) {
  std::vector<std::string> reversed(args.rbegin(), args.rend());  // CLI11 pops from the back
  try {
    app.parse(reversed);
  } catch (const CLI::ParseError& e) {
    return Exit(app, e, args, out, err);
  }
  return std::nullopt;
}

int UsageError(const CLI::App& app, const std::string& why, std::ostream& err) {
  err << ProgramName(app) << ": " << why << "\nRun with --help for more information.\n";
  return kExitUsage;
}

std::vector<std::string> FlagNames(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::Option* option : app.get_options()) {
    for (const std::string& name : option->get_lnames()) names.push_back("--" + name);
    for (const std::string& name : option->get_snames()) names.push_back("-" + name);
  }
  return names;
}

CLI::Validator Real(double lo, double hi) {
  std::ostringstream description;
  description << "REAL in [" << lo << ", " << hi << "]";
  return CLI::Validator(
      [lo, hi, range = description.str().substr(8)](std::string& value) -> std::string {
        char* end = nullptr;
        errno = 0;
        const double parsed = std::strtod(value.c_str(), &end);
        if (value.empty() || end != value.c_str() + value.size() || errno == ERANGE ||
            !std::isfinite(parsed) || parsed < lo || parsed > hi) {
          return "'" + value + "' is not a finite number in " + range;
        }
        return {};
      },
      description.str(), "Real");
}

CLI::Validator Endpoint() {
  return CLI::Validator(
      [](std::string& value) -> std::string {
        for (const char* scheme : {"tcp://", "ipc://", "inproc://"}) {
          const std::string prefix = scheme;
          if (value.rfind(prefix, 0) != 0 || value.size() == prefix.size()) continue;
          if (prefix != "tcp://") return {};
          const size_t colon = value.rfind(':');
          if (colon > prefix.size() && colon + 1 < value.size()) return {};
          break;
        }
        return "'" + value +
               "' is not a ZeroMQ endpoint (tcp://HOST:PORT with PORT a number or *, "
               "ipc://PATH, inproc://NAME)";
      },
      "ENDPOINT", "Endpoint");
}

}  // namespace sandtable::cli
