// ChildProcess: what the lab gives a child besides its arguments (its environment).
#include "sim/lab/child_process.h"

#include <stdlib.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace sandtable::sim {
namespace {

constexpr auto kDeadline = std::chrono::seconds(10);

// The child's stdout, every line, once it has exited.
std::vector<std::string> RunToEnd(const ChildSpec& spec) {
  Expected<std::unique_ptr<ChildProcess>> child = ChildProcess::Spawn(spec);
  EXPECT_TRUE(child.ok()) << child.status().ToString();
  if (!child.ok()) return {};
  std::vector<std::string> lines;
  const auto until = std::chrono::steady_clock::now() + kDeadline;
  while (!(*child)->stdout_closed() && std::chrono::steady_clock::now() < until) {
    for (std::string& line : (*child)->ReadLines()) lines.push_back(std::move(line));
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_TRUE((*child)->WaitFor(kDeadline));
  EXPECT_EQ((*child)->exit_code(), 0);
  return lines;
}

TEST(ChildProcessTest, EnvironmentIsTheLabsWithTheSpecsVariablesReplacingTheirNames) {
  const std::string log =
      (std::filesystem::temp_directory_path() / "sandtable_child_process_test.log").string();
  ASSERT_EQ(setenv("SANDTABLE_CHILD_TEST_KEPT", "kept", 1), 0);
  ASSERT_EQ(setenv("SANDTABLE_CHILD_TEST_SET", "the lab's", 1), 0);
  ChildSpec spec{"sh",
                 "test",
                 {"/bin/sh", "-c",
                  "echo \"$SANDTABLE_CHILD_TEST_KEPT\"; echo \"$SANDTABLE_CHILD_TEST_SET\"; "
                  "echo \"$SANDTABLE_CHILD_TEST_NEW\"; env | grep -c '^SANDTABLE_CHILD_TEST_SET='"},
                 log,
                 {"SANDTABLE_CHILD_TEST_SET=the child's", "SANDTABLE_CHILD_TEST_NEW=new"}};
  const std::vector<std::string> lines = RunToEnd(spec);
  EXPECT_EQ(lines, (std::vector<std::string>{"kept", "the child's", "new", "1"}));

  spec.env.clear();  // none given: exactly the lab's
  EXPECT_EQ(RunToEnd(spec), (std::vector<std::string>{"kept", "the lab's", "", "1"}));
  std::filesystem::remove(log);
}

}  // namespace
}  // namespace sandtable::sim
