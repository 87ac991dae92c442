// LabPainter: the lab's annotation client for chaos runs (docs/lab.md, "Chaos").
//
// On its own thread it paints strokes through the coordinator's annotation protocol, as a
// console or a wand client would: a stroke_begin, then one stroke_points request per point at
// `points_per_s`, up to `window` requests in flight, and records every accepted ack. When no
// ack comes for `ack_timeout` while requests are in flight (the link lost them), or its
// connection drops (the coordinator was killed: a monitor of the socket says so at once), it
// counts an outage from the last ack, drops the requests in flight (an
// unacknowledged request may or may not have been stored: it is not counted either way),
// reconnects with a new incarnation and, once the coordinator answers, begins a new stroke (the
// old one cannot go on: its next point index may be missing). The outage ends at the first ack
// after it.
//
// Verify() asks the coordinator for a snapshot (catch-up from 0) and checks that every
// acknowledged point is there, at its index in its stroke, with the value painted: `lost` counts
// the acknowledged points that are not (the chaos acceptance: 0).
//
// Point k of stroke s: (-0.25 + 0.004 (k mod 125), -0.2 + 0.01 (s mod 40), 0) metres in the table
// frame, exactly representable enough to compare as floats.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "common/base/status.h"
#include "net/curve.h"

namespace sandtable::sim {

struct LabPainterOptions {
  std::string requests_endpoint;  // the coordinator's ROUTER
  std::optional<net::CurveKeyPair> site_keys;
  double points_per_s = 40.0;
  int window = 8;
  std::chrono::milliseconds ack_timeout{500};
  uint64_t first_stroke_id = 900001;
  // INVALID_ARGUMENT: no endpoint, points_per_s not > 0, window < 1, ack_timeout not > 0.
  Status Check() const;
};

struct LabPainterOutage {
  double from_s = 0.0;  // the last ack before it, seconds after Start()
  double to_s = -1.0;   // the first ack after it; -1: none came
};

struct LabPainterResult {
  int strokes = 0;  // begun and acknowledged
  uint64_t requests_sent = 0;
  uint64_t points_acknowledged = 0;
  uint64_t refused = 0;  // acks with accepted = false
  std::string first_refusal;
  std::vector<LabPainterOutage> outages;
  // Verify():
  bool verified = false;
  uint64_t points_present = 0;  // acknowledged points found with their value
  uint64_t points_lost = 0;     // acknowledged points missing or changed
  std::string verify_error;
  nlohmann::json ToJson() const;
};

// The painted point k of stroke `stroke_id`.
Eigen::Vector3f LabPainterPoint(uint64_t stroke_id, uint32_t k);

class LabPainter {
 public:
  explicit LabPainter(LabPainterOptions options);
  ~LabPainter();
  LabPainter(const LabPainter&) = delete;
  LabPainter& operator=(const LabPainter&) = delete;

  void Start();
  void Stop();  // joins the thread; idempotent
  // Seconds since Start() of the latest ack (-1 before any).
  double last_ack_s() const;
  // Seconds since Start() of the first accepted ack at or after `s` (-1: none).
  double FirstAckAfter(double s) const;
  // After Stop(): checks the acknowledged points against the coordinator's snapshot.
  LabPainterResult Verify(std::chrono::milliseconds timeout);
  LabPainterResult result() const;

 private:
  void Run();

  LabPainterOptions options_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  LabPainterResult result_;
  // stroke id -> acknowledged point indices (each acknowledged once)
  std::map<uint64_t, std::vector<uint32_t>> acked_;
  std::vector<double> ack_times_s_;  // every accepted ack, in order
  std::chrono::steady_clock::time_point started_;
  std::atomic<int64_t> last_ack_ns_{-1};
};

}  // namespace sandtable::sim
