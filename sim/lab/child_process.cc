#include "sim/lab/child_process.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <deque>
#include <fstream>
#include <thread>

namespace sandtable::sim {

namespace {

// Async-signal-safe write of a C string (between fork and exec).
void WriteRaw(int fd, const char* text) {
  size_t left = std::strlen(text);
  while (left > 0) {
    const ssize_t n = write(fd, text, left);
    if (n <= 0) return;
    text += n;
    left -= static_cast<size_t>(n);
  }
}

}  // namespace

std::string SignalName(int signal) {
  const char* abbrev = sigabbrev_np(signal);
  return abbrev ? std::string("SIG") + abbrev : "signal " + std::to_string(signal);
}

Expected<std::unique_ptr<ChildProcess>> ChildProcess::Spawn(const ChildSpec& spec) {
  if (spec.argv.empty()) return InvalidArgumentError("child " + spec.name + ": empty command");
  std::unique_ptr<ChildProcess> child(new ChildProcess(spec));
  child->log_fd_ =
      open(spec.log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_APPEND | O_CLOEXEC, 0644);
  if (child->log_fd_ < 0) {
    return IoError("cannot open log " + spec.log_path + ": " + std::strerror(errno));
  }
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) return IoError(std::string("pipe: ") + std::strerror(errno));
  // Everything the child needs is prepared before fork: after it, only async-signal-safe calls.
  std::vector<char*> argv;
  for (const std::string& a : spec.argv) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::vector<std::string> env_strings;
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string entry(*e);
    const std::string name = entry.substr(0, entry.find('='));
    const bool replaced = std::any_of(spec.env.begin(), spec.env.end(), [&](const std::string& v) {
      return v.compare(0, name.size() + 1, name + "=") == 0;
    });
    if (!replaced) env_strings.push_back(entry);
  }
  env_strings.insert(env_strings.end(), spec.env.begin(), spec.env.end());
  std::vector<char*> envp;
  for (const std::string& e : env_strings) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) {
    close(fds[0]);
    close(fds[1]);
    return IoError(std::string("fork: ") + std::strerror(errno));
  }
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);  // the lab died before prctl took effect
    setpgid(0, 0);
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, nullptr);
    signal(SIGPIPE, SIG_DFL);
    dup2(fds[1], STDOUT_FILENO);
    dup2(child->log_fd_, STDERR_FILENO);
    const int null_fd = open("/dev/null", O_RDONLY);
    if (null_fd >= 0) dup2(null_fd, STDIN_FILENO);
    execve(argv[0], argv.data(), envp.data());
    WriteRaw(STDERR_FILENO, "sandtable-lab: cannot execute ");
    WriteRaw(STDERR_FILENO, argv[0]);
    WriteRaw(STDERR_FILENO, ": ");
    WriteRaw(STDERR_FILENO, std::strerror(errno));
    WriteRaw(STDERR_FILENO, "\n");
    _exit(127);
  }
  // Also from the parent, so the group exists before the first Signal() (no race with exec).
  setpgid(pid, pid);
  close(fds[1]);
  child->pid_ = pid;
  child->stdout_fd_ = fds[0];
  fcntl(child->stdout_fd_, F_SETFL, fcntl(child->stdout_fd_, F_GETFL) | O_NONBLOCK);
  return child;
}

ChildProcess::~ChildProcess() {
  if (pid_ > 0 && !exited_) {
    Signal(SIGKILL);
    WaitFor(std::chrono::milliseconds(5000));
  }
  if (stdout_fd_ >= 0) close(stdout_fd_);
  if (log_fd_ >= 0) close(log_fd_);
}

void ChildProcess::AppendToLog(const char* data, size_t size) {
  while (size > 0 && log_fd_ >= 0) {
    const ssize_t n = write(log_fd_, data, size);
    if (n <= 0) return;
    data += n;
    size -= static_cast<size_t>(n);
  }
}

std::vector<std::string> ChildProcess::ReadLines() {
  std::vector<std::string> lines;
  while (stdout_fd_ >= 0) {
    char chunk[4096];
    const ssize_t n = read(stdout_fd_, chunk, sizeof(chunk));
    if (n > 0) {
      AppendToLog(chunk, static_cast<size_t>(n));
      partial_.append(chunk, static_cast<size_t>(n));
      continue;
    }
    if (n < 0 && (errno == EAGAIN || errno == EINTR)) break;
    close(stdout_fd_);  // end of output (or a read error: treated the same)
    stdout_fd_ = -1;
  }
  size_t start = 0;
  for (size_t eol; (eol = partial_.find('\n', start)) != std::string::npos; start = eol + 1) {
    lines.push_back(partial_.substr(start, eol - start));
  }
  partial_.erase(0, start);
  if (stdout_fd_ < 0 && !partial_.empty()) {
    lines.push_back(partial_);
    partial_.clear();
  }
  return lines;
}

bool ChildProcess::Reap() {
  if (exited_ || pid_ <= 0) return exited_;
  int status = 0;
  struct rusage usage {};
  const pid_t r = wait4(pid_, &status, WNOHANG, &usage);
  if (r != pid_) return false;
  exited_ = true;
  cpu_s_ = static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
           1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
  max_rss_mb_ = static_cast<double>(usage.ru_maxrss) / 1024.0;  // Linux: kilobytes
  if (WIFEXITED(status)) exit_code_ = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) term_signal_ = WTERMSIG(status);
  return true;
}

std::string ChildProcess::DescribeExit() const {
  if (!exited_) return "still running";
  if (term_signal_) {
    return "killed by signal " + std::to_string(*term_signal_) + " (" + SignalName(*term_signal_) +
           ")";
  }
  return "exit status " + std::to_string(exit_code_.value_or(-1));
}

void ChildProcess::Signal(int signal) {
  if (pid_ > 0 && !exited_) kill(-pid_, signal);
}

bool ChildProcess::WaitFor(std::chrono::milliseconds deadline) {
  const auto until = std::chrono::steady_clock::now() + deadline;
  // Polls waitpid (a child's exit is an event without a file descriptor here); 5 ms steps.
  while (!Reap()) {
    if (std::chrono::steady_clock::now() >= until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

std::vector<std::string> ChildProcess::LogTail(int lines) const {
  std::ifstream in(spec_.log_path);
  std::deque<std::string> tail;
  for (std::string line; std::getline(in, line);) {
    tail.push_back(line);
    if (static_cast<int>(tail.size()) > lines) tail.pop_front();
  }
  return {tail.begin(), tail.end()};
}

}  // namespace sandtable::sim
