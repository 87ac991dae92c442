#include "sim/lab/supervisor.h"

#include <poll.h>
#include <signal.h>

#include "common/base/file_io.h"
#include "common/base/log.h"

namespace sandtable::sim {

Expected<ChildProcess*> Supervisor::Start(const ChildSpec& spec) {
  Expected<std::unique_ptr<ChildProcess>> child = ChildProcess::Spawn(spec);
  if (!child.ok()) return child.status();
  children_.push_back(std::move(*child));
  ST_RETURN_IF_ERROR(WriteProcessesJson());
  return children_.back().get();
}

Status Supervisor::WriteProcessesJson() const {
  if (processes_json_path_.empty()) return OkStatus();
  nlohmann::json list = nlohmann::json::array();
  for (const auto& child : children_) {
    list.push_back({{"name", child->name()}, {"pid", child->pid()}, {"role", child->spec().role}});
  }
  // All or nothing (temporary file, fsync, rename), so a reader never sees half a list.
  const nlohmann::json file{
      {"format", "sandtable.lab_processes"}, {"version", 1}, {"processes", list}};
  return WriteFileAtomically(processes_json_path_, file.dump(2) + "\n");
}

WaitOutcome Supervisor::WaitUntil(const std::function<bool()>& done,
                                  std::chrono::milliseconds deadline, const std::atomic<bool>& stop,
                                  const LineHandler& on_line) {
  dead_child_ = nullptr;
  const auto until = std::chrono::steady_clock::now() + deadline;
  while (true) {
    // Lines first: a child's last words (its ready line, or why it failed) arrive before its
    // death is noticed.
    for (const auto& child : children_) {
      for (const std::string& line : child->ReadLines()) {
        if (line.empty() || line.front() != '{') continue;
        Expected<report::ReportLine> parsed = report::ParseReportLineText(line);
        if (!parsed.ok()) {
          ++report_lines_.bad;
          report_lines_.last_error = child->name() + ": " + parsed.status().message();
          ST_LOG(kWarning) << child->name() << " printed a line that is not a report line ("
                           << parsed.status().message() << "): " << line;
          continue;
        }
        ++report_lines_.parsed;
        on_line(*child, *parsed);
      }
    }
    if (done()) return WaitOutcome::kDone;
    for (const auto& child : children_) {
      if (expected_exits_.count(child.get())) {
        if (child->Reap()) child->ReadLines();
        continue;
      }
      if (child->Reap()) {
        child->ReadLines();  // drain the pipe into the log
        dead_child_ = child.get();
        return WaitOutcome::kChildDied;
      }
    }
    if (stop.load()) return WaitOutcome::kStopped;
    const auto now = std::chrono::steady_clock::now();
    if (now >= until) return WaitOutcome::kDeadline;
    // Wake on output from any child, at the latest after 50 ms (exits, stop flag, deadline).
    std::vector<pollfd> fds;
    for (const auto& child : children_) {
      if (!child->stdout_closed()) fds.push_back({child->stdout_fd(), POLLIN, 0});
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - now);
    const int timeout_ms = static_cast<int>(std::min<int64_t>(50, left.count() + 1));
    poll(fds.data(), fds.size(), timeout_ms);
  }
}

WaitOutcome Supervisor::Watch(std::chrono::milliseconds period, const std::atomic<bool>& stop,
                              const LineHandler& on_line) {
  const WaitOutcome outcome = WaitUntil([] { return false; }, period, stop, on_line);
  return outcome == WaitOutcome::kDeadline ? WaitOutcome::kDone : outcome;
}

std::vector<std::string> Supervisor::TearDown(std::chrono::milliseconds grace) {
  std::vector<std::string> killed;
  const auto until = std::chrono::steady_clock::now() + grace;
  auto stop_all = [&](const std::vector<ChildProcess*>& group) {
    for (ChildProcess* child : group) child->Signal(SIGTERM);
    for (ChildProcess* child : group) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          until - std::chrono::steady_clock::now());
      if (!child->WaitFor(std::max(left, std::chrono::milliseconds(0)))) {
        child->Signal(SIGKILL);
        child->WaitFor(std::chrono::milliseconds(5000));
        killed.push_back(child->name());
      }
      child->ReadLines();
    }
  };
  // Nodes first, together (each says Goodbye to a coordinator that still listens), then the
  // rest one by one in reverse start order (coordinator, world).
  std::vector<ChildProcess*> nodes;
  for (const auto& child : children_) {
    if (child->spec().role == "node") nodes.push_back(child.get());
  }
  stop_all(nodes);
  for (auto it = children_.rbegin(); it != children_.rend(); ++it) {
    if ((*it)->spec().role != "node") stop_all({it->get()});
  }
  return killed;
}

}  // namespace sandtable::sim
