#include "sim/lab/lab_verdict.h"

#include <cmath>
#include <iomanip>
#include <sstream>

namespace sandtable::sim {

namespace {

std::string Mm(double value_mm) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(3) << value_mm << " mm";
  return s.str();
}

}  // namespace

Status LabVerdictOptions::Check() const {
  if (!(max_rms_mm >= 0.0) || !std::isfinite(max_rms_mm)) {
    return InvalidArgumentError("--max-rms-mm must be >= 0 (0: no bar)");
  }
  if (min_registration_pairs < 1 || min_unit_pairs < 1 || min_step_pairs < 1) {
    return InvalidArgumentError("lab verdict: the minimum sample counts must be >= 1");
  }
  return OkStatus();
}

std::string StepNotMeasured(const nlohmann::json& photometric, const std::string& surface,
                            int min_pairs) {
  if (!photometric.is_object() || !photometric.contains(surface) ||
      !photometric[surface].is_object()) {
    return "no " + surface + " step figure";
  }
  const int pairs = photometric[surface].value("pairs", 0);
  if (pairs < min_pairs) {
    return std::to_string(pairs) + " pairs of samples on the " + surface + " (at least " +
           std::to_string(min_pairs) + ")";
  }
  return "";
}

std::vector<LabReason> JudgeLabRun(const LabResult& r, const LabVerdictOptions& o) {
  std::vector<LabReason> reasons;
  if (r.failure) return reasons;
  if (!r.registration) {
    reasons.push_back({"registration not measured", "the run holds no registration figure"});
  } else {
    const RegistrationReport& reg = *r.registration;
    const int pairs = reg.site.all.count;
    if (pairs < o.min_registration_pairs) {
      reasons.push_back({"registration not measured",
                         std::to_string(pairs) + " point-projector pairs for the site (at least " +
                             std::to_string(o.min_registration_pairs) + ")"});
    } else if (o.max_rms_mm > 0.0 && reg.site.all.rms_mm > o.max_rms_mm) {
      reasons.push_back({"registration over its bar", Mm(reg.site.all.rms_mm) + " rms > " +
                                                          Mm(o.max_rms_mm) + " (--max-rms-mm)"});
    }
    for (const auto& [id, errors] : reg.per_unit) {
      if (errors.all.count < o.min_unit_pairs) {
        reasons.push_back({"registration not measured",
                           "unit " + std::to_string(id) + ": " + std::to_string(errors.all.count) +
                               " pairs (at least " + std::to_string(o.min_unit_pairs) + ")"});
      }
    }
    if (r.measured_with_true_placement && reg.num_building_points > 0) {
      reasons.push_back({"model not found",
                         "the nodes found no placement of the model; the registration was "
                         "measured with the true placement, which no node had"});
    }
  }
  // A unit the lab itself killed (--kill-unit) is left out by design, not by a fault.
  const int killed = r.kill.is_object() ? r.kill.value("unit", -1) : -1;
  for (const auto& [id, why] : r.unit_failures) {
    if (static_cast<int>(id) == killed) continue;
    reasons.push_back({"a unit left out", "unit " + std::to_string(id) + ": " + why});
  }
  if (r.photometric.is_object() && r.photometric.contains("max_step_pct_per_5mm")) {
    const std::string table = StepNotMeasured(r.photometric, "table", o.min_step_pairs);
    if (!table.empty()) reasons.push_back({"a blend figure not measured", "table step: " + table});
  }
  return reasons;
}

}  // namespace sandtable::sim
