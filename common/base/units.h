// Unit conversions. Lengths in the table frame are metres (double); errors are reported in mm
// and px. A number without a type of its own carries its unit in its name (_m, _mm, _px, _deg,
// _rad, _ms, _s, _hz). Durations in code are std::chrono types.
#pragma once

#include <chrono>
#include <numbers>

namespace sandtable {

constexpr double kMmPerM = 1000.0;
constexpr double kMPerInch = 0.0254;
constexpr double kMPerFoot = 0.3048;

constexpr double DegToRad(double angle_deg) { return angle_deg * std::numbers::pi / 180.0; }
constexpr double RadToDeg(double angle_rad) { return angle_rad * 180.0 / std::numbers::pi; }
constexpr double MToMm(double length_m) { return length_m * kMmPerM; }
constexpr double MmToM(double length_mm) { return length_mm / kMmPerM; }

using Seconds = std::chrono::duration<double>;
using Milliseconds = std::chrono::duration<double, std::milli>;

}  // namespace sandtable
