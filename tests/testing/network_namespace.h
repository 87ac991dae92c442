// InOwnNetworkNamespace: runs a test's body in a child process with a network namespace of its
// own (unshare(CLONE_NEWNET)), after `setup` (a shell command: ip link, ip addr) has built its
// interfaces there; programs the body starts (ChildProcess) share that namespace, and it and
// its interfaces are gone when the child exits. The body returns 0 and a text for the parent
// to check, or another code and what went wrong. kSkipped when this machine cannot make a
// namespace or the interfaces (not root, no veth), with the reason.
#pragma once

#include <sched.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <functional>
#include <string>

namespace sandtable::test_support {

struct NamespaceRun {
  static constexpr int kSkipped = 77;
  int code = -1;  // the body's return, kSkipped, or -1 when the child did not exit normally
  std::string text;
};

inline NamespaceRun InOwnNetworkNamespace(const std::string& setup,
                                          const std::function<int(std::string*)>& body) {
  NamespaceRun run;
  int pipe_fds[2];
  if (::pipe(pipe_fds) != 0) {
    run.text = "pipe failed";
    return run;
  }
  const pid_t child = ::fork();
  if (child < 0) {
    run.text = "fork failed";
    return run;
  }
  if (child == 0) {
    ::close(pipe_fds[0]);
    std::string text;
    int code = 0;
    if (::unshare(CLONE_NEWNET) != 0) {
      text = "no network namespace here: unshare(CLONE_NEWNET) failed (needs root)";
      code = NamespaceRun::kSkipped;
    } else if (std::system(("ip link set lo up && " + setup).c_str()) != 0) {
      text = "cannot build the namespace's interfaces (" + setup + ")";
      code = NamespaceRun::kSkipped;
    } else {
      code = body(&text);
    }
    const ssize_t written = ::write(pipe_fds[1], text.data(), text.size());
    (void)written;
    ::_exit(code);
  }
  ::close(pipe_fds[1]);
  char buffer[1024];
  ssize_t n = 0;
  while ((n = ::read(pipe_fds[0], buffer, sizeof(buffer))) > 0) run.text.append(buffer, n);
  ::close(pipe_fds[0]);
  int status = 0;
  if (::waitpid(child, &status, 0) == child && WIFEXITED(status)) run.code = WEXITSTATUS(status);
  return run;
}

}  // namespace sandtable::test_support
