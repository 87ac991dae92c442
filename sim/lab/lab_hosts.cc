#include "sim/lab/lab_hosts.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "common/base/log.h"

namespace sandtable::sim {
namespace {

// Runs `argv` (searched on PATH) and waits; its stderr (and stdout) in the error.
Status Run(const std::vector<std::string>& argv) {
  int fds[2];
  if (::pipe(fds) != 0) return IoError("pipe failed");
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    return IoError("fork failed");
  }
  if (pid == 0) {
    ::dup2(fds[1], STDOUT_FILENO);
    ::dup2(fds[1], STDERR_FILENO);
    ::close(fds[0]);
    ::close(fds[1]);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    ::execvp(args[0], args.data());
    std::fprintf(stderr, "cannot run %s (is iproute2 installed?)", args[0]);
    ::_exit(127);
  }
  ::close(fds[1]);
  std::string output;
  char buffer[512];
  ssize_t n = 0;
  while ((n = ::read(fds[0], buffer, sizeof(buffer))) > 0) output.append(buffer, n);
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return OkStatus();
  std::string command;
  for (const std::string& a : argv) command += (command.empty() ? "" : " ") + a;
  while (!output.empty() && (output.back() == '\n' || output.back() == ' ')) output.pop_back();
  return UnavailableError("`" + command + "` failed: " + output);
}

// What `argv` printed (empty when it failed).
std::string Output(const std::vector<std::string>& argv) {
  std::string command;
  for (const std::string& a : argv) command += a + " ";
  FILE* pipe = ::popen((command + "2>/dev/null").c_str(), "r");
  if (pipe == nullptr) return {};
  std::string output;
  char buffer[512];
  size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) output.append(buffer, n);
  ::pclose(pipe);
  return output;
}

// The full path of `program` on PATH or in the system directories ("" when absent): children
// are started with execv.
std::string FindProgram(const std::string& program) {
  std::string path = std::getenv("PATH") != nullptr ? std::getenv("PATH") : "";
  path += ":/usr/sbin:/sbin:/usr/bin:/bin";
  size_t start = 0;
  while (start <= path.size()) {
    const size_t end = std::min(path.find(':', start), path.size());
    const std::string candidate = path.substr(start, end - start) + "/" + program;
    if (end > start && ::access(candidate.c_str(), X_OK) == 0) return candidate;
    start = end + 1;
  }
  return {};
}

bool Alive(pid_t pid) { return ::kill(pid, 0) == 0 || errno == EPERM; }

// Namespaces and bridges of labs that died without tearing down ("stl<pid>-*", "stb<pid>").
void DeleteLeftovers() {
  const std::string namespaces = Output({"ip", "netns", "list"});
  size_t at = 0;
  while ((at = namespaces.find("stl", at)) != std::string::npos) {
    const size_t end = namespaces.find_first_of(" \n", at);
    const std::string name = namespaces.substr(at, end - at);
    at = end;
    const size_t dash = name.find('-');
    if (dash == std::string::npos) continue;
    const pid_t pid = static_cast<pid_t>(std::atoi(name.substr(3, dash - 3).c_str()));
    if (pid <= 0 || Alive(pid)) continue;
    (void)Run({"ip", "netns", "del", name});
    (void)Run({"ip", "link", "del", "stb" + std::to_string(pid)});
  }
}

}  // namespace

NetnsHosts::NetnsHosts(std::string bridge, std::string prefix, std::string subnet)
    : bridge_(std::move(bridge)), prefix_(std::move(prefix)), subnet_(std::move(subnet)) {
  lab_address_ = subnet_ + "1";
}

Expected<std::unique_ptr<NetnsHosts>> NetnsHosts::Create() {
  if (::geteuid() != 0) {
    return UnavailableError(
        "--hosts netns needs root (it creates network namespaces, a bridge and veth pairs)");
  }
  const std::string ip = FindProgram("ip");
  if (ip.empty()) return UnavailableError("--hosts netns needs iproute2's `ip` (not found)");
  DeleteLeftovers();
  const pid_t pid = ::getpid();
  const std::string bridge = "stb" + std::to_string(pid);
  // One /24 per lab process: from its pid, the next one no interface of this host uses, so
  // concurrent labs on one machine stay apart.
  const std::string in_use = Output({"ip", "-o", "-4", "addr", "show"});
  int third = pid % 250;
  for (int tries = 0; tries < 250; ++tries, third = (third + 1) % 250) {
    if (in_use.find(" 10.250." + std::to_string(third) + ".") == std::string::npos) break;
  }
  const std::string subnet = "10.250." + std::to_string(third) + ".";
  std::unique_ptr<NetnsHosts> hosts(
      new NetnsHosts(bridge, "stl" + std::to_string(pid) + "-", subnet));
  hosts->ip_ = ip;
  for (const std::vector<std::string>& step :
       {std::vector<std::string>{"ip", "link", "add", bridge, "type", "bridge"},
        std::vector<std::string>{"ip", "addr", "add", hosts->lab_address_ + "/24", "dev", bridge},
        std::vector<std::string>{"ip", "link", "set", bridge, "up"}}) {
    if (Status done = Run(step); !done.ok()) {
      return done.WithContext("--hosts netns: cannot create the run's bridge");
    }
  }
  return hosts;
}

NetnsHosts::~NetnsHosts() {
  for (const Host& host : hosts_) {
    if (Status deleted = Run({"ip", "netns", "del", host.netns}); !deleted.ok()) {
      ST_LOG(kWarning) << "lab hosts: " << deleted.ToString();
    }
  }
  if (Status deleted = Run({"ip", "link", "del", bridge_}); !deleted.ok()) {
    ST_LOG(kWarning) << "lab hosts: " << deleted.ToString();
  }
}

Expected<std::string> NetnsHosts::AddHost(const std::string& name) {
  if (Find(name) != nullptr) return InvalidArgumentError("lab hosts: " + name + " exists");
  if (hosts_.size() >= 240) return OutOfRangeError("lab hosts: at most 240 hosts a run");
  Host host;
  host.name = name;
  host.netns = prefix_ + name;
  // Interface names have at most 15 characters: "stb<pid>p<index>".
  host.port = "st" + std::to_string(::getpid()) + "p" + std::to_string(hosts_.size());
  host.address = subnet_ + std::to_string(10 + hosts_.size());
  const std::string cidr = host.address + "/24";
  for (const std::vector<std::string>& step : {
           std::vector<std::string>{"ip", "netns", "add", host.netns},
           std::vector<std::string>{"ip", "link", "add", host.port, "type", "veth", "peer", "name",
                                    "eth0", "netns", host.netns},
           std::vector<std::string>{"ip", "link", "set", host.port, "master", bridge_, "up"},
           std::vector<std::string>{"ip", "-n", host.netns, "addr", "add", cidr, "dev", "eth0"},
           std::vector<std::string>{"ip", "-n", host.netns, "link", "set", "eth0", "up"},
           std::vector<std::string>{"ip", "-n", host.netns, "link", "set", "lo", "up"},
       }) {
    if (Status done = Run(step); !done.ok()) {
      (void)Run({"ip", "netns", "del", host.netns});
      return done.WithContext("--hosts netns: cannot create host " + name);
    }
  }
  hosts_.push_back(host);
  return host.address;
}

const NetnsHosts::Host* NetnsHosts::Find(const std::string& name) const {
  for (const Host& host : hosts_) {
    if (host.name == name) return &host;
  }
  return nullptr;
}

std::vector<std::string> NetnsHosts::Wrap(const std::string& name,
                                          std::vector<std::string> argv) const {
  const Host* host = Find(name);
  if (host == nullptr) return argv;
  argv.insert(argv.begin(), {ip_, "netns", "exec", host->netns});
  return argv;
}

std::string NetnsHosts::Address(const std::string& name) const {
  const Host* host = Find(name);
  return host == nullptr ? std::string() : host->address;
}

std::string NetnsHosts::Reachable(const std::string& name, const std::string& endpoint) const {
  const Host* host = Find(name);
  if (host == nullptr) return endpoint;
  for (const std::string any : {"tcp://0.0.0.0:", "tcp://*:"}) {
    if (endpoint.rfind(any, 0) == 0)
      return "tcp://" + host->address + ":" + endpoint.substr(any.size());
  }
  return endpoint;
}

Status NetnsHosts::SetLink(const std::string& name, bool up) {
  const Host* host = Find(name);
  if (host == nullptr) return NotFoundError("lab hosts: no host " + name);
  return Run({"ip", "link", "set", host->port, up ? "up" : "down"});
}

Status NetnsHosts::CapBandwidth(const std::string& name, int kbit_per_s) {
  const Host* host = Find(name);
  if (host == nullptr) return NotFoundError("lab hosts: no host " + name);
  if (kbit_per_s <= 0) return InvalidArgumentError("lab hosts: a bandwidth cap must be > 0");
  // A token bucket on the bridge's port: what leaves the bridge towards the host.
  return Run({"tc", "qdisc", "replace", "dev", host->port, "root", "tbf", "rate",
              std::to_string(kbit_per_s) + "kbit", "burst", "32kbit", "latency", "400ms"});
}

}  // namespace sandtable::sim
