// Supervisor: the lab's children (world, coordinator, nodes) and the event loop that waits on
// them: their report lines (cluster/report_lines.h), an early death, the deadline, or the lab's
// own stop request (SIGINT/SIGTERM).
//
// Every line a child prints on stdout that starts with '{' is read as a report line and handed
// to the caller; one that does not parse is counted (report_lines()) and logged with the child's
// name and the reason, never dropped silently. Other lines are free text for people (kept in the
// log only). Nothing is parsed with regexes.
// processes.json (name, pid, role of every child) is rewritten after every start so tests can
// find the processes.
// Tear-down: SIGTERM to every child (nodes first, then the coordinator, then the world), then
// SIGKILL to whatever still runs after the grace period; every child is reaped.
// Not thread-safe: one thread runs the supervisor.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "cluster/report_lines.h"
#include "common/base/status.h"
#include "sim/lab/child_process.h"

namespace sandtable::sim {

enum class WaitOutcome {
  kDone,       // the condition holds
  kDeadline,   // the deadline passed first
  kStopped,    // the stop flag was raised (SIGINT/SIGTERM on the lab)
  kChildDied,  // a child exited; see dead_child()
};

class Supervisor {
 public:
  // `processes_json_path`: where the list of children is kept ("" = nowhere).
  explicit Supervisor(std::string processes_json_path)
      : processes_json_path_(std::move(processes_json_path)) {}
  ~Supervisor() { TearDown(std::chrono::milliseconds(3000)); }

  Expected<ChildProcess*> Start(const ChildSpec& spec);

  using LineHandler = std::function<void(ChildProcess& child, const report::ReportLine& line)>;
  // Runs the loop until `done()` holds (checked after every batch of lines and at least every
  // 50 ms), a child exits, `stop` is raised, or `deadline` passes.
  WaitOutcome WaitUntil(const std::function<bool()>& done, std::chrono::milliseconds deadline,
                        const std::atomic<bool>& stop, const LineHandler& on_line);
  // Runs the loop for `period` (children watched, their lines handled): kDone once it passed,
  // else kChildDied or kStopped.
  WaitOutcome Watch(std::chrono::milliseconds period, const std::atomic<bool>& stop,
                    const LineHandler& on_line);
  // The report lines read so far, and those that did not parse.
  const report::ReportLineCounts& report_lines() const { return report_lines_; }

  // The child whose death ended the last WaitUntil (nullptr otherwise).
  const ChildProcess* dead_child() const { return dead_child_; }
  // A child the caller is about to stop on purpose: its exit no longer ends a WaitUntil.
  void ExpectExit(const ChildProcess* child) { expected_exits_.insert(child); }
  const std::vector<std::unique_ptr<ChildProcess>>& children() const { return children_; }

  // SIGTERM everyone (reverse start order: nodes, coordinator, world), SIGKILL after `grace`.
  // Returns the names of children that had to be killed. Idempotent.
  std::vector<std::string> TearDown(std::chrono::milliseconds grace);

 private:
  Status WriteProcessesJson() const;

  std::string processes_json_path_;
  std::vector<std::unique_ptr<ChildProcess>> children_;
  const ChildProcess* dead_child_ = nullptr;
  std::set<const ChildProcess*> expected_exits_;
  report::ReportLineCounts report_lines_;
};

}  // namespace sandtable::sim
