// The lab's verdict on a run that completed: what it failed, and which of its figures it did not
// measure. A run passes only what it measured: a figure from fewer samples than its minimum is
// "not measured" with the reason, never a pass.
//
// Reasons a completed run fails (each one line a person can act on, in this order):
//   registration not measured (no result, or fewer than min_registration_pairs point-projector
//     pairs for the site, or fewer than min_unit_pairs for a unit);
//   registration over its bar: the site's rms above max_rms_mm (`sandtable-lab run
//     --max-rms-mm`; 0 turns the bar off);
//   model not found: the scene has structures and the nodes found no placement of the model
//     (the registration was then measured with the true placement, which no node had);
//   a unit left out: it reported no calibration, with its reason (not the unit the lab killed
//     itself, --kill-unit);
//   a blend figure not measured: the nodes blended but the table's step metric found fewer than
//     min_step_pairs pairs (the walls' only where the scene has walls to measure).
// Figures the summary shows as "not measured" without failing the run: walls' and roofs' steps
// of a scene that has none.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/base/status.h"
#include "sim/lab/lab_report.h"

namespace sandtable::sim {

struct LabVerdictOptions {
  double max_rms_mm = 1.0;  // 0: no bar
  int min_registration_pairs = 200;
  int min_unit_pairs = 30;
  int min_step_pairs = 200;
  Status Check() const;
};

// The reasons `result` fails, empty when it passes. A run that already failed or was
// interrupted (result.failure) is judged by that alone: no reasons are added.
std::vector<LabReason> JudgeLabRun(const LabResult& result, const LabVerdictOptions& options);

// Why a step figure of the photometric JSON (`surface`: "table", "walls", "roofs") is not
// measured, or "" when it is: absent, or fewer than min_pairs pairs.
std::string StepNotMeasured(const nlohmann::json& photometric, const std::string& surface,
                            int min_pairs);

}  // namespace sandtable::sim
