#include "common/cli/command_line.h"

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

int Exit(const CLI::App& app, const CLI::ParseError& e, std::ostream& out, std::ostream& err) {
  if (e.get_exit_code() == static_cast<int>(CLI::ExitCodes::Success)) {
    app.exit(e, out, err);  // --help: the selected (sub)command's help on `out`
    return kExitOk;
  }
  return UsageError(Selected(app), e.what(), err);
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
    return Exit(app, e, out, err);
  }
  return std::nullopt;
}

std::optional<int> Parse(CLI::App& app, const std::vector<std::string>& args, std::ostream& out,
                         std::ostream& err) {
  std::vector<std::string> reversed(args.rbegin(), args.rend());  // CLI11 pops from the back
  try {
    app.parse(reversed);
  } catch (const CLI::ParseError& e) {
    return Exit(app, e, out, err);
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
