// Tracker sources: whatever produces 6-DOF sensor poses in the tracker frame (a Polhemus device
// over USB, a recorded trajectory, the scripted virtual wand of the lab).
//
// Frames and units: tracker_from_sensor maps points of the sensor (wand) frame to the tracker
// (transmitter) frame, translation in metres, rotation a unit quaternion (Eigen w, x, y, z;
// every source converts to this at its boundary). table_from_tracker (tracker calibration)
// takes poses to the table frame.
// Contract: Poll() never blocks and never aborts; a source with no device reports kNoDevice
// with a message and keeps being polled (a device plugged in later is picked up).
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/geometry/rigid3.h"

namespace sandtable::coordinator {

using TrackerClock = std::chrono::steady_clock;

struct TrackerSample {
  uint32_t sensor_index = 0;  // 0-based station / sensor
  Rigid3d tracker_from_sensor;
  bool button_pressed = false;
  double source_time_s = 0.0;  // time in the source's own timeline (replay file, device)
};

enum class TrackerState {
  kNoDevice,    // nothing connected (USB: no Polhemus device found)
  kConnecting,  // found, being opened and configured
  kStreaming,   // delivering samples
  kEnded,       // a replay reached its end (and does not loop)
  kError,       // unrecoverable for this source (message says why)
};
const char* TrackerStateName(TrackerState state);

class TrackerSource {
 public:
  virtual ~TrackerSource() = default;
  // Appends the samples that became available up to `now` (in order). Never blocks.
  virtual Status Poll(TrackerClock::time_point now, std::vector<TrackerSample>* out) = 0;
  virtual TrackerState state() const = 0;
  // One line for logs and the status endpoint ("replay user1_cup0.traj 100 Hz, 271 samples").
  virtual std::string Describe() const = 0;
  // Nominal sample rate (Hz); 0 when unknown.
  virtual double rate_hz() const = 0;
};

}  // namespace sandtable::coordinator
