// sandtable-node doctor: checks one unit's set-up and prints a checklist with what to do for each
// failure (docs/devices.md, "Doctor"). It takes the unit's own flags and configuration files
// (the command line the unit runs with, `doctor` in front), opens its devices and asks nothing
// of the site but a time request.
//
//   sandtable-node doctor --id 3 --coordinator tcp://10.0.0.2:5555,tcp://10.0.0.2:5556
//       --projector window:0 --camera video:0 --factory unit-3.json --curve-keys site.key
//
// The checks, in order (a check whose input failed is skipped, saying which):
//   factory file   loads and is valid; its age (a warning past kFactoryOldDays)
//   key file       --curve-keys / --enroll: mode 0600 and a matching pair (missing: not enrolled
//                  yet, a warning)
//   display        opens; its size against the factory file's projector
//   camera         opens and captures; its size against the factory file's camera, bit depth
//   light          the camera sees the projector: white against black, the share of the image
//                  lit and the contrast there
//   latency        show-to-capture: white shown on black, captured until seen (several times:
//                  median and spread)
//   exposure       a longer exposure gives a brighter image (the exposure is under control)
//   coordinator    answers a time request within DoctorOptions::coordinator_timeout (with the
//                  site key when there is one; --coordinator discover: found by its beacon)
// Exit status: 0 when no check failed (warnings allowed), 1 when one did, 2 for a bad flag.
#pragma once

#include <chrono>
#include <string>
#include <vector>

#include "node/app/node_config.h"

namespace sandtable::node {

inline constexpr int kFactoryOldDays = 365;

enum class CheckVerdict { kOk, kWarn, kFail, kSkipped };
const char* CheckVerdictName(CheckVerdict verdict);  // "ok", "warn", "FAIL", "skip"

struct DoctorCheck {
  std::string name;
  CheckVerdict verdict = CheckVerdict::kSkipped;
  std::string detail;  // what was found, with figures
  std::string todo;    // what to do (failures and warnings)
};

struct DoctorOptions {
  std::chrono::milliseconds coordinator_timeout{2000};
  std::chrono::milliseconds discovery_timeout{10000};
  std::chrono::milliseconds latency_window{2000};  // the longest a flash may take to be seen
  int latency_flashes = 5;
  // The camera sees the projector where white is brighter than black by at least this share
  // of the camera's full scale, on at least min_lit_share of its image.
  double min_contrast_of_full_scale = 0.05;
  double min_lit_share = 0.02;
  // Two exposures (the second `exposure_ratio` times the first): the brighter must be at least
  // min_exposure_gain times the darker in the lit region.
  double exposure_short_s = 0.004;
  double exposure_ratio = 4.0;
  double min_exposure_gain = 1.3;
};

// Runs every check on the unit `config` describes (Check() passed).
std::vector<DoctorCheck> RunDoctorChecks(NodeConfig config, const DoctorOptions& options);
// The checklist as printed: one line per check ("[ok]   camera   ..."), the todo indented
// below a failure or warning, and a last line "ready: yes" or "ready: no (N of M failed)".
std::string FormatChecklist(const std::vector<DoctorCheck>& checks);
bool Ready(const std::vector<DoctorCheck>& checks);

// `args`: what follows `doctor` on the command line.
int RunDoctor(const std::vector<std::string>& args);

}  // namespace sandtable::node
