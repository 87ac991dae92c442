// ChildProcess: one program the lab runs (world, coordinator, a node), started with fork/exec.
//
// The child's stdout is a pipe the lab reads (for its JSON lines); everything it writes on
// stdout and stderr also lands in its log file (stderr directly, stdout copied by the lab as
// it reads). The child runs in its own process group (so a Ctrl-C on the lab's terminal reaches
// only the lab, which then tears the site down in order) and with PR_SET_PDEATHSIG = SIGKILL
// (so a lab that dies without tearing down leaves no orphan).
// Not thread-safe: one supervisor thread owns its children.
// Failure: Spawn returns IO_ERROR when the log cannot be opened or fork fails; a program that
// cannot be executed exits 127 with the reason in its log.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/base/status.h"

namespace sandtable::sim {

struct ChildSpec {
  std::string name;               // "world", "coordinator", "node-3"
  std::string role;               // "world", "coordinator", "node"
  std::vector<std::string> argv;  // argv[0]: the program's path
  std::string log_path;
  // NAME=VALUE set in the child's environment (the lab's own, with these replacing a variable
  // of the same name).
  std::vector<std::string> env = {};
};

class ChildProcess {
 public:
  static Expected<std::unique_ptr<ChildProcess>> Spawn(const ChildSpec& spec);
  // Kills the child's process group (SIGKILL) and reaps it if it still runs.
  ~ChildProcess();
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  const ChildSpec& spec() const { return spec_; }
  const std::string& name() const { return spec_.name; }
  pid_t pid() const { return pid_; }
  int stdout_fd() const { return stdout_fd_; }

  // Reads what is available on the stdout pipe without blocking, copies it to the log and
  // returns the complete lines. At end of output the last partial line is returned too.
  std::vector<std::string> ReadLines();
  bool stdout_closed() const { return stdout_fd_ < 0; }

  // Reaps the child if it has exited (non-blocking); true once it has.
  bool Reap();
  bool exited() const { return exited_; }
  // After exit: "exit status 1", "killed by signal 9 (SIGKILL)".
  std::string DescribeExit() const;
  std::optional<int> exit_code() const { return exit_code_; }
  // After exit: the CPU time (user + system, s) the child used (wait4's rusage; its own
  // children it did not reap are not counted).
  double cpu_s() const { return cpu_s_; }
  double max_rss_mb() const { return max_rss_mb_; }  // peak resident memory (MiB)
  std::optional<int> term_signal() const { return term_signal_; }

  // Sends `signal` to the child's process group (no-op once reaped).
  void Signal(int signal);
  // Reaps within `deadline`; false when still running then.
  bool WaitFor(std::chrono::milliseconds deadline);

  // The last `lines` lines of the log file.
  std::vector<std::string> LogTail(int lines) const;

 private:
  explicit ChildProcess(ChildSpec spec) : spec_(std::move(spec)) {}
  void AppendToLog(const char* data, size_t size);

  ChildSpec spec_;
  pid_t pid_ = -1;
  int stdout_fd_ = -1;
  int log_fd_ = -1;
  std::string partial_;
  bool exited_ = false;
  std::optional<int> exit_code_, term_signal_;
  double cpu_s_ = 0.0, max_rss_mb_ = 0.0;
};

// "SIGKILL" for 9 (the abbreviation sigabbrev_np gives), "signal N" when unknown.
std::string SignalName(int signal);

}  // namespace sandtable::sim
