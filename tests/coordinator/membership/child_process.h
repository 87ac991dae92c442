// ChildProcess: spawns a program for multi-process tests, reads its stdout lines with
// deadlines, signals it, and kills it (SIGKILL) if still running when destroyed.
// ReadReadyLine: the one-line JSON readiness hand-shake of the programs (cluster/report_lines.h),
// e.g. {"ready":"sandtable-coordinator","requests":"tcp://...","events":"tcp://..."}.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

extern char** environ;

namespace sandtable::testing {

// What the pipe read by ReadLine carries (stderr is otherwise the test's own).
enum class ChildOutput { kStdout, kStdoutAndStderr };

class ChildProcess {
 public:
  explicit ChildProcess(const std::vector<std::string>& argv,
                        ChildOutput output = ChildOutput::kStdout) {
    int fds[2];
    if (pipe(fds) != 0) return;
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[1], STDOUT_FILENO);
    if (output == ChildOutput::kStdoutAndStderr) {
      posix_spawn_file_actions_adddup2(&actions, fds[1], STDERR_FILENO);
    }
    posix_spawn_file_actions_addclose(&actions, fds[0]);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    if (posix_spawn(&pid_, args[0], &actions, nullptr, args.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&actions);
    close(fds[1]);
    stdout_fd_ = fds[0];
  }
  ~ChildProcess() {
    if (running()) {
      Signal(SIGKILL);
      Wait();
    }
    if (stdout_fd_ >= 0) close(stdout_fd_);
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  bool running() const { return pid_ > 0 && !exited_; }
  pid_t pid() const { return pid_; }
  void Signal(int sig) {
    if (running()) kill(pid_, sig);
  }
  // Exit status (or 128 + signal).
  int Wait() {
    if (!running()) return exit_code_;
    int status = 0;
    waitpid(pid_, &status, 0);
    exited_ = true;
    exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    return exit_code_;
  }

  // The next line the child prints on stdout, or nullopt at the deadline or end of output.
  std::optional<std::string> ReadLine(std::chrono::milliseconds deadline) {
    const auto until = std::chrono::steady_clock::now() + deadline;
    while (true) {
      const size_t eol = buffer_.find('\n');
      if (eol != std::string::npos) {
        std::string line = buffer_.substr(0, eol);
        buffer_.erase(0, eol + 1);
        return line;
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          until - std::chrono::steady_clock::now());
      if (left.count() <= 0) return std::nullopt;
      pollfd p{stdout_fd_, POLLIN, 0};
      if (poll(&p, 1, static_cast<int>(left.count())) <= 0) continue;
      char chunk[512];
      const ssize_t n = read(stdout_fd_, chunk, sizeof(chunk));
      if (n <= 0) return std::nullopt;
      buffer_.append(chunk, static_cast<size_t>(n));
    }
  }

 private:
  pid_t pid_ = -1;
  int stdout_fd_ = -1;
  bool exited_ = false;
  int exit_code_ = -1;
  std::string buffer_;
};

// Everything the child prints until it closes its output (or the deadline), then its exit
// status (or 128 + signal; -1 if it is still running at the deadline).
inline int RunToEnd(ChildProcess& child, std::chrono::milliseconds deadline,
                    std::string* output = nullptr) {
  const auto until = std::chrono::steady_clock::now() + deadline;
  std::string text;
  while (true) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        until - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    std::optional<std::string> line = child.ReadLine(left);
    if (!line) break;
    text += *line + "\n";
  }
  if (output) *output = text;
  if (std::chrono::steady_clock::now() >= until && child.running()) return -1;
  return child.Wait();
}

// Runs `program` with `args` to its end (stdout and stderr both into *output); its exit status
// as RunToEnd gives it.
inline int RunProgram(const std::string& program, std::vector<std::string> args,
                      std::chrono::milliseconds deadline, std::string* output) {
  args.insert(args.begin(), program);
  ChildProcess child(args, ChildOutput::kStdoutAndStderr);
  return RunToEnd(child, deadline, output);
}

// The next stdout line of `child`, which must be its readiness line: a JSON object whose
// "ready" member is `program`. nullopt (and *error says why) at the deadline, at the end of
// output, or for any other line: the hand-shake is JSON, not free text.
inline std::optional<nlohmann::json> ReadReadyLine(ChildProcess& child, const std::string& program,
                                                   std::chrono::milliseconds deadline,
                                                   std::string* error = nullptr) {
  auto fail = [&](const std::string& why) -> std::optional<nlohmann::json> {
    if (error) *error = program + ": " + why;
    return std::nullopt;
  };
  const std::optional<std::string> line = child.ReadLine(deadline);
  if (!line) return fail("no readiness line within the deadline (or the program exited)");
  const nlohmann::json json = nlohmann::json::parse(*line, nullptr, /*allow_exceptions=*/false);
  if (json.is_discarded() || !json.is_object()) return fail("not a JSON object: " + *line);
  const auto ready = json.find("ready");
  if (ready == json.end() || !ready->is_string() || ready->get<std::string>() != program) {
    return fail("\"ready\" is not \"" + program + "\": " + *line);
  }
  return json;
}

// A string member of a readiness line ("" when absent or not a string).
inline std::string ReadyString(const nlohmann::json& line, const std::string& key) {
  const auto it = line.find(key);
  return it != line.end() && it->is_string() ? it->get<std::string>() : std::string();
}

}  // namespace sandtable::testing
