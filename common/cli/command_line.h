// Command lines of every Sandtable program and benchmark, on CLI11, with one policy:
//   - `--help` (`-h`) prints the help text, which lists every flag with its type, range and
//     default, on stdout: exit 0;
//   - any error in the command line (an unknown flag, a missing value or required flag, a value
//     that is not of the flag's type or outside its range, flags that exclude each other)
//     prints "PROGRAM: MESSAGE" naming the flag on stderr, then a hint to --help: exit 2
//     (kExitUsage). `--heartbeat-ms abc` is an error, never 0.
//
// A program builds a CLI::App, registers its flags with typed variables and validators
// (Integer, Real, Endpoint below; CLI::IsMember), then:
//   if (std::optional<int> exit = cli::Parse(app, argc, argv)) return *exit;
// Errors that only show after parsing (a file that does not load) are reported by the program
// itself; it may use UsageError() for those that are the user's command line.
#pragma once

#include <charconv>
#include <iostream>
#include <optional>
#include <ostream>
#include <string>
#include <system_error>
#include <type_traits>
#include <vector>

#include <CLI/CLI.hpp>

namespace sandtable::cli {

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

// House defaults for an app and its subcommands: defaults shown in --help, help flag -h,--help.
// Call before adding options (defaults apply to options added afterwards).
void Configure(CLI::App& app);

// Parses argv (argv[0] is the program). Returns nullopt when the program should go on, else
// the exit code to return (0 after --help, kExitUsage after an error, both already printed).
std::optional<int> Parse(CLI::App& app, int argc, const char* const* argv,
                         std::ostream& out = std::cout, std::ostream& err = std::cerr);
// The same for arguments that exclude the program name (e.g. those after a subcommand).
std::optional<int> Parse(CLI::App& app, const std::vector<std::string>& args,
                         std::ostream& out = std::cout, std::ostream& err = std::cerr);

// Unknown flags and subcommands get the closest known name ("did you mean --site?"), and a
// missing subcommand the list of them.
// Prints "NAME: why" and the hint to --help on `err`; returns kExitUsage.
int UsageError(const CLI::App& app, const std::string& why, std::ostream& err = std::cerr);

// For an option whose default is a sentinel ("none", "required") outside its own range: --help
// shows no default for it (say what its absence means in its description).
inline CLI::Option* NoDefaultShown(CLI::Option* option) { return option->default_str(""); }

// The long names ("--name") and short names ("-n") of every option `app` registered, help
// included, in registration order: what --help must list.
std::vector<std::string> FlagNames(const CLI::App& app);

// Validators (each error message is prefixed with the flag's name by CLI11). Use them instead
// of CLI::Range, whose integer conversion reads "010" as octal 8 and "-1" as 2^64 - 1 for an
// unsigned value, and whose real range lets "nan" through.
//
// A decimal integer in [lo, hi]: no sign for an unsigned type, no '+', no base prefix, no
// leading zero (CLI11 would read "010" as octal), no fraction.
template <typename T>
CLI::Validator Integer(T lo, T hi);
// A finite real number in [lo, hi].
CLI::Validator Real(double lo, double hi);
// A ZeroMQ endpoint: tcp://HOST:PORT (PORT may be * or 0), ipc://PATH or inproc://NAME.
CLI::Validator Endpoint();

// ---- implementation ----

template <typename T>
CLI::Validator Integer(T lo, T hi) {
  static_assert(std::is_integral_v<T>);
  return CLI::Validator(
      [lo, hi](std::string& value) -> std::string {
        T parsed{};
        const char* begin = value.data();
        const char* end = value.data() + value.size();
        // from_chars (base 10) takes no '+', no base prefix and, for unsigned types, no '-'.
        const auto [stop, error] = std::from_chars(begin, end, parsed, 10);
        const size_t digits = value.size() > 0 && value[0] == '-' ? 1 : 0;
        const bool leading_zero = value.size() > digits + 1 && value[digits] == '0';
        if (value.empty() || error != std::errc() || stop != end || leading_zero || parsed < lo ||
            parsed > hi) {
          return "'" + value + "' is not a decimal integer in [" + std::to_string(lo) + ", " +
                 std::to_string(hi) + "]";
        }
        return {};
      },
      "INT in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]", "Integer");
}

}  // namespace sandtable::cli
