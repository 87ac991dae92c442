// The operator's 2D test patterns, drawn on the CPU once per size and id (they do not change
// from frame to frame): the unit's id in large digits, and colour bars. RGB8 (R first), row 0
// at the top, the projector's size.
#pragma once

#include <cstdint>

#include <opencv2/core.hpp>

namespace sandtable::node {

// The id in white digits as tall as ~60 % of the image, centred, on black, with a 1-px white
// border around the image (shows the image's edges on the surfaces).
cv::Mat ProjectorIdPattern(cv::Size size_px, uint32_t id);

// Eight vertical bars of equal width: white, yellow, cyan, green, magenta, red, blue, black.
cv::Mat ColourBarsPattern(cv::Size size_px);

}  // namespace sandtable::node
