// The nodes' own prediction of their registration error (the solve's covariance,
// node/calibration/cluster_uncertainty.h, carried in self_calibration_report.json) beside the
// lab's measurement of it (registration_metric.h): per unit, in projector px over every surface
// (what the prediction is made in) and in mm on the table (the prediction's mm figure covers
// the unit's points on the table only). ratio = measured / predicted; the target is within 2x
// either way (docs/lab.md). A unit without a prediction, or with no measured pairs, has no
// ratio ("not predicted" / "not measured"), never a pass.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/base/ids.h"
#include "sim/lab/registration_metric.h"

namespace sandtable::sim {

struct PredictionRow {
  NodeId unit = kInvalidNodeId;
  double predicted_px = -1.0;  // < 0: not predicted
  double predicted_mm = -1.0;  // on the table; < 0: not predicted
  double measured_px = 0.0;    // all surfaces
  double measured_table_mm = 0.0;
  int pairs = 0, table_pairs = 0;
  std::string weak_direction;
  double weak_share = 0.0;
  // measured / predicted; < 0 when either side is missing.
  double ratio_px() const;
  double ratio_mm() const;
};

struct PredictionComparison {
  std::vector<PredictionRow> units;
  double sigma_px = 0.0;
  std::string undetermined;
};

// `runner_report`: self_calibration_report.json (its bundle.units[id].predicted_*).
PredictionComparison ComparePrediction(const RegistrationReport& measured,
                                       const nlohmann::json& runner_report);
nlohmann::json PredictionJson(const PredictionComparison& comparison);
std::string PredictionMarkdown(const PredictionComparison& comparison);

}  // namespace sandtable::sim
