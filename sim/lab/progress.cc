#include "sim/lab/progress.h"

#include <cstdio>

namespace sandtable::sim {

namespace {
constexpr int kBarWidth = 24;
}

std::string Progress::ElapsedText() const {
  char text[32];
  std::snprintf(text, sizeof(text), "%.1f s", Elapsed_s());
  return text;
}

double Progress::Elapsed_s() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::Begin(const std::string& phase, int total) {
  if (active_) End();
  phase_ = phase;
  waiting_for_.clear();
  note_key_.clear();
  note_.clear();
  total_ = total;
  done_ = 0;
  active_ = true;
  start_ = std::chrono::steady_clock::now();
  Draw(false);
}

void Progress::Update(int done) {
  if (!active_ || done == done_) return;
  done_ = done;
  Draw(false);
}

void Progress::Tick(const std::function<std::string()>& waiting_for) {
  if (!active_) return;
  const auto now = std::chrono::steady_clock::now();
  const std::chrono::steady_clock::duration gap =
      tty_ ? std::chrono::milliseconds(200) : plain_gap_;
  if (now - last_tick_ < gap || (!tty_ && now - start_ < gap)) return;
  last_tick_ = now;
  waiting_for_ = waiting_for();
  if (tty_) {
    Draw(false);
    return;
  }
  const std::string time_text = ElapsedText();
  out_ << "lab: " << phase_ << " "
       << (total_ > 0 ? std::to_string(done_) + "/" + std::to_string(total_) + " " : "") << "("
       << time_text << (waiting_for_.empty() ? "" : "; waiting for " + waiting_for_) << ")\n"
       << std::flush;
}

void Progress::Note(const std::string& key, const std::string& text,
                    const std::string& plain_text) {
  if (!active_) return;
  const bool new_key = key != note_key_;
  note_key_ = key;
  note_ = text;
  if (tty_) {
    Draw(false);
    return;
  }
  if (!new_key) return;
  const std::string time_text = ElapsedText();
  out_ << "lab: " << phase_ << " (" << time_text
       << "): " << (plain_text.empty() ? text : plain_text) << "\n"
       << std::flush;
}

void Progress::End(const std::string& outcome) {
  if (!active_) return;
  if (outcome == "ok" && total_ > 0) done_ = total_;
  seconds_.emplace_back(phase_, Elapsed_s());
  const std::string time_text = ElapsedText();
  if (tty_) {
    Draw(true);
    out_ << "  " << outcome << "\n" << std::flush;
  } else {
    out_ << "lab: " << phase_ << ": " << outcome << " (" << time_text << ")\n" << std::flush;
  }
  active_ = false;
}

void Progress::Draw(bool final_line) {
  const std::string time_text = ElapsedText();
  const std::string counts =
      total_ > 0 ? " " + std::to_string(done_) + "/" + std::to_string(total_) : "";
  if (!tty_) {
    if (!final_line)
      out_ << "lab: " << phase_ << counts << " (" << time_text << ")\n" << std::flush;
    return;
  }
  std::string bar(kBarWidth, ' ');
  const int filled = total_ > 0 ? kBarWidth * done_ / total_ : (final_line ? kBarWidth : 0);
  for (int i = 0; i < filled; ++i) bar[i] = '=';
  if (filled < kBarWidth && filled > 0) bar[filled] = '>';
  out_ << "\r\033[K[" << bar << "] " << phase_ << counts << "  " << time_text
       << (final_line || note_.empty() ? "" : "  " + note_)
       << (final_line || waiting_for_.empty() ? "" : "  waiting for " + waiting_for_) << std::flush;
}

}  // namespace sandtable::sim
