// The lab's progress on the terminal (sim/lab/progress.h): a phase that waits says for how long
// and for whom, on its bar or in a plain line.
#include "sim/lab/progress.h"

#include <chrono>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>

namespace sandtable::sim {
namespace {

using std::chrono::milliseconds;

constexpr milliseconds kPlainGap{50};
constexpr milliseconds kPastTheGap{80};

TEST(ProgressTest, AWaitingPhaseSaysForHowLongAndForWhomInPlainLines) {
  std::ostringstream out;
  Progress progress(out, /*tty=*/false, kPlainGap);
  progress.Begin("calibration held", 3);
  progress.Tick([] { return std::string("node-0, node-2"); });  // too soon: nothing
  EXPECT_EQ(out.str().find("waiting for"), std::string::npos) << out.str();
  std::this_thread::sleep_for(kPastTheGap);
  progress.Tick([] { return std::string("node-0, node-2"); });
  EXPECT_NE(out.str().find("lab: calibration held 0/3 ("), std::string::npos) << out.str();
  EXPECT_NE(out.str().find("; waiting for node-0, node-2)"), std::string::npos) << out.str();
  progress.End();
  EXPECT_NE(out.str().find("lab: calibration held: ok"), std::string::npos) << out.str();
}

TEST(ProgressTest, OnATerminalTheBarCarriesWhatItWaitsForUntilTheEnd) {
  std::ostringstream out;
  Progress progress(out, /*tty=*/true);
  progress.Begin("start nodes", 3);
  std::this_thread::sleep_for(kPastTheGap * 3);  // past the bar's redraw interval (200 ms)
  progress.Tick([] { return std::string("node-1"); });
  EXPECT_NE(out.str().find("start nodes 0/3"), std::string::npos) << out.str();
  EXPECT_NE(out.str().find("waiting for node-1"), std::string::npos) << out.str();
  progress.End();
  const std::string last = out.str().substr(out.str().rfind('\r'));
  EXPECT_EQ(last.find("waiting for"), std::string::npos) << "the final line: " << last;
  EXPECT_NE(last.find("ok"), std::string::npos) << last;
}

TEST(ProgressTest, ANotePrintsAPlainLineOnlyWhenItsKeyChanges) {
  std::ostringstream out;
  Progress progress(out, /*tty=*/false, kPlainGap);
  progress.Begin("calibration held", 3);
  progress.Note("pre-pass", "round by unit 0: pre-pass (unit 1)");
  progress.Note("pre-pass", "round by unit 0: pre-pass (unit 2)");  // same step: no line
  progress.Note("solve", "round by unit 0: solve");
  const std::string text = out.str();
  EXPECT_NE(text.find("): round by unit 0: pre-pass (unit 1)\n"), std::string::npos) << text;
  EXPECT_EQ(text.find("pre-pass (unit 2)"), std::string::npos) << text;
  EXPECT_NE(text.find("): round by unit 0: solve\n"), std::string::npos) << text;
  progress.Begin("show", 0);  // a new phase forgets the note
  progress.Note("solve", "round by unit 0: solve");
  EXPECT_NE(out.str().find("lab: show ("), std::string::npos) << out.str();
}

TEST(ProgressTest, OnATerminalTheBarShowsEveryNoteUntilTheEnd) {
  std::ostringstream out;
  Progress progress(out, /*tty=*/true);
  progress.Begin("calibration held", 3);
  progress.Note("structured light, colour 1", "colour 1 frame 12 capture (units 0, 2)");
  EXPECT_NE(out.str().find("calibration held 0/3"), std::string::npos) << out.str();
  EXPECT_NE(out.str().find("colour 1 frame 12 capture (units 0, 2)"), std::string::npos)
      << out.str();
  progress.End();
  const std::string last = out.str().substr(out.str().rfind('\r'));
  EXPECT_EQ(last.find("colour 1"), std::string::npos) << "the final line: " << last;
}

}  // namespace
}  // namespace sandtable::sim
