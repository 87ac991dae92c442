// Progress of the lab's phases on the terminal (stderr).
//
// On a TTY: one line per phase redrawn in place, a bar with counts and the elapsed time,
//   [=========>          ] start nodes  2/3  1.4 s
// Otherwise (logs, CI): plain lines, one when a phase starts, one per count change, one at the end,
//   lab: start nodes: 2/3 (1.4 s)
// Every phase's wall time is kept for the report.
#pragma once

#include <chrono>
#include <functional>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

namespace sandtable::sim {

class Progress {
 public:
  // `tty`: draw bars (the caller decides, e.g. isatty(STDERR_FILENO)).
  // `plain_gap`: how often a waiting phase prints a plain line (Tick).
  Progress(std::ostream& out, bool tty,
           std::chrono::milliseconds plain_gap = std::chrono::milliseconds(10000))
      : out_(out), tty_(tty), plain_gap_(plain_gap) {}

  void Begin(const std::string& phase, int total);
  void Update(int done);
  // While waiting: the elapsed time and what is awaited ("node-0, node-2"), redrawn on a TTY
  // (at most 5 times a second), a plain line every plain_gap otherwise.
  // `waiting_for` is asked only when a line is due.
  void Tick(const std::function<std::string()>& waiting_for);
  // What the phase's work is doing now (e.g. a calibration round's stage), shown on the bar;
  // a plain line (`plain_text`, or `text` when empty) is printed when `key` differs from the
  // last note's (the bar shows every `text`). Cleared by Begin.
  void Note(const std::string& key, const std::string& text, const std::string& plain_text = "");
  // Ends the current phase: "ok" or a short failure word.
  void End(const std::string& outcome = "ok");

  // (phase, seconds) of every ended phase, in order.
  const std::vector<std::pair<std::string, double>>& phase_seconds() const { return seconds_; }

 private:
  void Draw(bool final_line);
  double Elapsed_s() const;
  std::string ElapsedText() const;  // "1.4 s"

  std::ostream& out_;
  bool tty_;
  std::chrono::milliseconds plain_gap_;
  std::string phase_;
  int total_ = 0, done_ = -1;
  bool active_ = false;
  std::string waiting_for_;
  std::string note_key_, note_;
  std::chrono::steady_clock::time_point start_, last_tick_;
  std::vector<std::pair<std::string, double>> seconds_;
};

}  // namespace sandtable::sim
