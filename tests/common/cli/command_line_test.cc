// common/cli/command_line.h: the exit-code policy (0 after --help, 2 naming the flag after any
// command-line error), FlagNames, and the Endpoint validator, in process.
#include "common/cli/command_line.h"

#include <sstream>

#include <gtest/gtest.h>

#include "tests/common/cli/help_text.h"

namespace sandtable::cli {
namespace {

struct Program {
  int count = 3;
  double rate_hz = 1.0;
  std::string endpoint = "tcp://127.0.0.1:*";
  bool quick = false;
  CLI::App app{"a test program", "prog"};
  CLI::App* sub = nullptr;
  int sub_value = 0;
  Program() {
    Configure(app);
    app.add_option("--count", count, "how many")->check(cli::Integer(1, 10));
    app.add_option("-r,--rate-hz", rate_hz, "rate, Hz")->check(cli::Real(0.001, 1000.0));
    app.add_option("--endpoint", endpoint, "where")->check(Endpoint());
    app.add_flag("--quick", quick, "fast");
    sub = app.add_subcommand("sub", "a subcommand");
    sub->add_option("--value", sub_value, "a value")->required();
  }
  // Parses; returns the exit code (-1: go on) and what went to stdout / stderr.
  int Run(const std::vector<std::string>& args, std::string* out_text = nullptr,
          std::string* err_text = nullptr) {
    std::ostringstream out, err;
    std::optional<int> exit = Parse(app, args, out, err);
    if (out_text) *out_text = out.str();
    if (err_text) *err_text = err.str();
    return exit ? *exit : -1;
  }
};

TEST(CommandLineTest, ValuesAreTypedAndRangeChecked) {
  Program p;
  EXPECT_EQ(p.Run({"--count", "7", "-r", "2.5", "--quick"}), -1);
  EXPECT_EQ(p.count, 7);
  EXPECT_EQ(p.rate_hz, 2.5);
  EXPECT_TRUE(p.quick);
  for (const std::vector<std::string>& bad :
       std::vector<std::vector<std::string>>{{"--count", "abc"},
                                             {"--count", "0"},
                                             {"--count", "11"},
                                             {"--count", "2.5"},
                                             {"--count", "0x5"},
                                             {"--count", "010"},
                                             {"--count", "+5"},
                                             {"--rate-hz", "nan"},
                                             {"--rate-hz", "inf"},
                                             {"--count"},
                                             {"--rate-hz", "-1"},
                                             {"--rate-hz", "fast"},
                                             {"--endpoint", "localhost"},
                                             {"--endpoint", "tcp://"},
                                             {"--endpoint", "tcp://host"}}) {
    Program q;
    std::string err;
    EXPECT_EQ(q.Run(bad, nullptr, &err), kExitUsage) << bad.front();
    EXPECT_NE(err.find(bad.front()), std::string::npos) << "names the flag: " << err;
    EXPECT_EQ(err.rfind("prog: ", 0), 0u) << err;
    EXPECT_EQ(err.find("in in"), std::string::npos) << err;
  }
  Program unknown;
  std::string err;
  EXPECT_EQ(unknown.Run({"--colour", "red"}, nullptr, &err), kExitUsage);
  EXPECT_NE(err.find("--colour"), std::string::npos) << err;
}

TEST(CommandLineTest, EndpointsAccepted) {
  for (const std::string good :
       {"tcp://127.0.0.1:*", "tcp://127.0.0.1:0", "tcp://*:5555", "ipc:///tmp/x", "inproc://a"}) {
    Program p;
    EXPECT_EQ(p.Run({"--endpoint", good}), -1) << good;
  }
}

TEST(CommandLineTest, HelpListsEveryRegisteredFlagAndExitsZero) {
  Program p;
  std::string out;
  EXPECT_EQ(p.Run({"--help"}, &out), kExitOk);
  const std::vector<std::string> names = FlagNames(p.app);
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()), testing::FlagsInHelp(out)) << out;
  EXPECT_EQ(names, (std::vector<std::string>{"--help", "-h", "--count", "--rate-hz", "-r",
                                             "--endpoint", "--quick"}));
  EXPECT_NE(out.find("sub"), std::string::npos) << "lists the subcommands";
}

TEST(CommandLineTest, SubcommandErrorsAndHelpNameTheSubcommand) {
  Program p;
  std::string out, err;
  EXPECT_EQ(p.Run({"sub", "--help"}, &out), kExitOk);
  EXPECT_EQ(testing::FlagsInHelp(out), (std::set<std::string>{"-h", "--help", "--value"})) << out;
  Program q;
  EXPECT_EQ(q.Run({"sub", "--value", "x"}, nullptr, &err), kExitUsage);
  EXPECT_EQ(err.rfind("prog sub: ", 0), 0u) << err;
  EXPECT_NE(err.find("--value"), std::string::npos) << err;
  Program r;
  EXPECT_EQ(r.Run({"sub"}, nullptr, &err), kExitUsage);
  EXPECT_NE(err.find("--value"), std::string::npos) << "required: " << err;
}

// A mistyped flag or subcommand gets the name meant; a missing subcommand the list of them; a
// sentinel default is not shown.
TEST(CommandLineTest, TyposGetTheNameMeantAndMissingSubcommandsTheList) {
  Program p;
  std::string err;
  EXPECT_EQ(p.Run({"--cuont", "3"}, nullptr, &err), kExitUsage);
  EXPECT_NE(err.find("did you mean --count (not --cuont)?"), std::string::npos) << err;
  Program far;
  EXPECT_EQ(far.Run({"--colour", "red"}, nullptr, &err), kExitUsage);
  EXPECT_EQ(err.find("did you mean"), std::string::npos) << "nothing close: " << err;
  Program sub;
  EXPECT_EQ(sub.Run({"sub", "--valeu", "1"}, nullptr, &err), kExitUsage);
  EXPECT_NE(err.find("did you mean --value"), std::string::npos) << err;

  CLI::App app{"a program with subcommands", "tool"};
  Configure(app);
  app.require_subcommand(1);
  app.add_subcommand("run", "runs");
  app.add_subcommand("sweep", "sweeps");
  int unit = -1;
  NoDefaultShown(
      app.add_option("--unit", unit, "a unit (none by default)")->check(Integer(0, 100)));
  for (const std::vector<std::string>& args :
       std::vector<std::vector<std::string>>{{}, {"rnu"}, {"bogus"}}) {
    std::ostringstream out, errs;
    EXPECT_EQ(Parse(app, args, out, errs), kExitUsage);
    const std::string text = errs.str();
    EXPECT_NE(text.find("the subcommands are run, sweep"), std::string::npos) << text;
    if (!args.empty()) {
      EXPECT_NE(text.find("'" + args[0] + "' is not a subcommand"), std::string::npos) << text;
    }
    if (!args.empty() && args[0] == "rnu") {
      EXPECT_NE(text.find("did you mean run?"), std::string::npos) << text;
    }
  }
  std::ostringstream help, none;
  EXPECT_EQ(Parse(app, {"--help"}, help, none), kExitOk);
  EXPECT_NE(help.str().find("--unit INT"), std::string::npos) << help.str();
  EXPECT_EQ(help.str().find("=-1"), std::string::npos)
      << "a sentinel default shown: " << help.str();
}

}  // namespace
}  // namespace sandtable::cli
