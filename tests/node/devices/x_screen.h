// What the X server shows (tests under Xvfb), through one display connection of our own (opened on
// first use, kept). Kept apart from the tests because Xlib's macros (None, Status, Bool) clash with
// GoogleTest's and Sandtable's names.
#pragma once

#include <optional>

#include <opencv2/core.hpp>

namespace sandtable::node::testing {

// The pixels of `area` of screen 0 as RGB8 (CV_8UC3, R first); empty when there is no display
// or its visual is not 8-bit TrueColor.
cv::Mat ReadXScreen(cv::Rect area);
// The size of screen 0, or nullopt without a display.
std::optional<cv::Size> XScreenSize();

}  // namespace sandtable::node::testing
