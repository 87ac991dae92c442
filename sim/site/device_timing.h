// DeviceTiming: how a unit's real projector and camera shift what a capture shows in time
// (docs/world.md, "Device timing"). The default is the ideal device of the first sites: a
// capture is exposed when it is asked for and shows exactly the frame last sent.
//
// Projector: a frame sent at time t is on the table from the first refresh (period
// 1 / refresh_hz, phase fixed per unit) at least lag_frames refreshes after t.
// Camera (camera_fps > 0): exposes continuously at camera_fps from a phase fixed per unit;
// an exposure becomes readable camera_latency_s after it starts; the driver keeps the newest
// queue_frames unread exposures and a read returns the oldest of them (so a program that did
// not read for a while first gets frames older than its request), or waits for the next one.
// drop_rate of the exposures never arrive; repeat_rate of the reads return the previous
// read's picture again under a new index and time (a driver's duplicate). With
// auto_exposure_drift > 0 a capture at the camera's own exposure (exposure 0 asked) drifts
// by that relative amount over auto_exposure_period_s; an exposure asked for explicitly is a
// locked exposure and does not drift.
#pragma once

#include <string>

#include "common/base/status.h"

namespace sandtable::sim {

struct DeviceTiming {
  double refresh_hz = 60.0;
  int lag_frames = 0;
  double camera_fps = 0.0;  // 0: the ideal camera (exposed when asked)
  double camera_latency_s = 0.0;
  int queue_frames = 1;
  double drop_rate = 0.0;
  double repeat_rate = 0.0;
  double auto_exposure_drift = 0.0;
  double auto_exposure_period_s = 20.0;

  // Whether a capture shows exactly the frame last sent (the other fields then do nothing).
  bool Ideal() const { return lag_frames == 0 && camera_fps == 0.0 && auto_exposure_drift == 0.0; }
  bool operator==(const DeviceTiming&) const = default;
  // OK, or the field out of range: "timing.lag_frames = 12 must be in [0, 10]".
  Status Check() const;
};

// A unit that looks like real hardware: a 60 Hz projector showing a frame two refreshes after
// it was sent, a 30 fps camera with 10 ms from exposure to readable frame and a two-frame
// driver queue, 5 % of reads a repeated frame, 2 % of exposures lost. Its exposure does not
// drift: a node cannot yet lock the world camera's exposure (the capture request asks for an
// exposure, it cannot fix the camera's own), so a drift is for sites that set it.
DeviceTiming RealHardwareTiming();

// "ideal" or "real" (the lab's --device-timing); INVALID_ARGUMENT naming both otherwise.
Expected<DeviceTiming> DeviceTimingPreset(const std::string& name);

}  // namespace sandtable::sim
