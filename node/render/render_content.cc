#include "node/render/render_content.h"

#include <cmath>

namespace sandtable::node {

const char* TestPatternName(TestPattern pattern) {
  switch (pattern) {
    case TestPattern::kNone:
      return "none";
    case TestPattern::kProjectorId:
      return "id";
    case TestPattern::kTableGrid:
      return "grid";
    case TestPattern::kWhite:
      return "white";
    case TestPattern::kRawWhite:
      return "raw-white";
    case TestPattern::kColourBars:
      return "bars";
    case TestPattern::kBlack:
      return "black";
  }
  return "none";
}

std::optional<TestPattern> TestPatternFromName(const std::string& name) {
  for (TestPattern p :
       {TestPattern::kNone, TestPattern::kProjectorId, TestPattern::kTableGrid, TestPattern::kWhite,
        TestPattern::kRawWhite, TestPattern::kColourBars, TestPattern::kBlack}) {
    if (name == TestPatternName(p)) return p;
  }
  return std::nullopt;
}

Eigen::Vector3d SunDirection(double time_of_day_h, double max_elevation_deg) {
  const double day = std::fmod(std::fmod(time_of_day_h, 24.0) + 24.0, 24.0);
  const double phase = M_PI * (day - 6.0) / 12.0;  // 0 at sunrise, pi at sunset
  const double elevation = max_elevation_deg * M_PI / 180.0 * std::sin(phase);
  // Azimuth from east (+x) through south (-y) to west (-x) over the day.
  const double azimuth = phase;
  return Eigen::Vector3d(std::cos(azimuth) * std::cos(elevation),
                         -std::sin(azimuth) * std::cos(elevation), std::sin(elevation))
      .normalized();
}

}  // namespace sandtable::node
