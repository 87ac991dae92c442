#include "sim/site/device_timing.h"

#include <cmath>

namespace sandtable::sim {

namespace {

Status Range(const char* field, double value, double lo, double hi) {
  if (std::isfinite(value) && value >= lo && value <= hi) return OkStatus();
  return InvalidArgumentError("timing." + std::string(field) + " = " + std::to_string(value) +
                              " must be in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                              "]");
}

}  // namespace

Status DeviceTiming::Check() const {
  ST_RETURN_IF_ERROR(Range("refresh_hz", refresh_hz, 1.0, 1000.0));
  ST_RETURN_IF_ERROR(Range("lag_frames", lag_frames, 0, 10));
  ST_RETURN_IF_ERROR(Range("camera_fps", camera_fps, 0.0, 1000.0));
  if (camera_fps != 0.0 && camera_fps < 1.0) {
    return InvalidArgumentError("timing.camera_fps = " + std::to_string(camera_fps) +
                                " must be 0 (the ideal camera) or at least 1");
  }
  ST_RETURN_IF_ERROR(Range("camera_latency_s", camera_latency_s, 0.0, 1.0));
  ST_RETURN_IF_ERROR(Range("queue_frames", queue_frames, 1, 16));
  ST_RETURN_IF_ERROR(Range("drop_rate", drop_rate, 0.0, 0.5));
  ST_RETURN_IF_ERROR(Range("repeat_rate", repeat_rate, 0.0, 0.5));
  ST_RETURN_IF_ERROR(Range("auto_exposure_drift", auto_exposure_drift, 0.0, 0.9));
  return Range("auto_exposure_period_s", auto_exposure_period_s, 0.1, 3600.0);
}

DeviceTiming RealHardwareTiming() {
  DeviceTiming t;
  t.refresh_hz = 60.0;
  t.lag_frames = 2;
  t.camera_fps = 30.0;
  t.camera_latency_s = 0.010;
  t.queue_frames = 2;
  t.drop_rate = 0.02;
  t.repeat_rate = 0.05;
  return t;
}

Expected<DeviceTiming> DeviceTimingPreset(const std::string& name) {
  if (name == "ideal") return DeviceTiming{};
  if (name == "real") return RealHardwareTiming();
  return InvalidArgumentError("device timing '" + name + "' is neither 'ideal' nor 'real'");
}

}  // namespace sandtable::sim
