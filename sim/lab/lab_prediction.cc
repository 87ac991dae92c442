#include "sim/lab/lab_prediction.h"

#include <cstdio>
#include <sstream>

namespace sandtable::sim {
namespace {

std::string Fixed(double value, int digits) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.*f", digits, value);
  return text;
}

double Ratio(double measured, double predicted, int pairs) {
  return predicted > 0 && pairs > 0 ? measured / predicted : -1.0;
}

std::string RatioText(double ratio) {
  if (ratio < 0) return "-";
  const bool within = ratio >= 0.5 && ratio <= 2.0;
  return within ? Fixed(ratio, 2) : "**" + Fixed(ratio, 2) + "**";
}

}  // namespace

double PredictionRow::ratio_px() const { return Ratio(measured_px, predicted_px, pairs); }
double PredictionRow::ratio_mm() const {
  return Ratio(measured_table_mm, predicted_mm, table_pairs);
}

PredictionComparison ComparePrediction(const RegistrationReport& measured,
                                       const nlohmann::json& runner_report) {
  PredictionComparison out;
  const nlohmann::json bundle = runner_report.is_object() && runner_report.contains("bundle")
                                    ? runner_report["bundle"]
                                    : nlohmann::json::object();
  out.sigma_px = bundle.value("sigma_px", 0.0);
  out.undetermined = bundle.value("undetermined", std::string());
  const nlohmann::json units = bundle.value("units", nlohmann::json::object());
  for (const auto& [id, errors] : measured.per_unit) {
    PredictionRow row;
    row.unit = id;
    row.measured_px = errors.all.rms_px;
    row.pairs = errors.all.count;
    row.measured_table_mm = errors.table.rms_mm;
    row.table_pairs = errors.table.count;
    const std::string key = std::to_string(id);
    if (units.is_object() && units.contains(key) && units[key].is_object()) {
      const nlohmann::json& u = units[key];
      row.predicted_px = u.value("predicted_rms_px", -1.0);
      row.predicted_mm = u.value("predicted_rms_mm", -1.0);
      row.weak_direction = u.value("weak_direction", std::string());
      row.weak_share = u.value("weak_share", 0.0);
    }
    out.units.push_back(row);
  }
  return out;
}

nlohmann::json PredictionJson(const PredictionComparison& c) {
  nlohmann::json units = nlohmann::json::object();
  for (const PredictionRow& r : c.units) {
    units[std::to_string(r.unit)] = {
        {"predicted_rms_px", r.predicted_px}, {"predicted_table_rms_mm", r.predicted_mm},
        {"measured_rms_px", r.measured_px},   {"measured_table_rms_mm", r.measured_table_mm},
        {"ratio_px", r.ratio_px()},           {"ratio_table_mm", r.ratio_mm()},
        {"weak_direction", r.weak_direction}, {"weak_share", r.weak_share}};
  }
  return {{"sigma_px", c.sigma_px}, {"undetermined", c.undetermined}, {"units", units}};
}

std::string PredictionMarkdown(const PredictionComparison& c) {
  std::ostringstream md;
  md << "### Predicted against measured\n\n"
     << "Each unit's own prediction (1 sigma, from the solve's covariance with the observation "
        "noise it measured, "
     << Fixed(c.sigma_px, 3)
     << " px) beside the lab's measurement; ratio = measured / predicted, target within 2x "
        "either way (bold when outside).";
  if (!c.undetermined.empty()) md << " Left to the gauge: " << c.undetermined << ".";
  md << "\n\n| unit | predicted (px) | measured (px) | ratio | predicted, table (mm) | measured, "
        "table (mm) | ratio | what the data tell apart least |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- |\n";
  for (const PredictionRow& r : c.units) {
    md << "| " << r.unit << " | "
       << (r.predicted_px >= 0 ? Fixed(r.predicted_px, 3) : std::string("not predicted")) << " | "
       << (r.pairs > 0 ? Fixed(r.measured_px, 3) : std::string("not measured")) << " | "
       << RatioText(r.ratio_px()) << " | "
       << (r.predicted_mm >= 0 ? Fixed(r.predicted_mm, 3) : std::string("not predicted")) << " | "
       << (r.table_pairs > 0 ? Fixed(r.measured_table_mm, 3) : std::string("not measured")) << " | "
       << RatioText(r.ratio_mm()) << " | "
       << (r.weak_direction.empty()
               ? std::string("-")
               : r.weak_direction + " (" + Fixed(r.weak_share * 100.0, 0) + " % of the variance)")
       << " |\n";
  }
  md << "\n";
  return md.str();
}

}  // namespace sandtable::sim
