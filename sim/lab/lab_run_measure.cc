// The lab run's metrics phase (lab_run_internal.h): every unit's exported calibration against
// the truth, and the figures the nodes reported.
#include "sim/lab/lab_run_internal.h"

namespace sandtable::sim::lab_internal {

bool LabRun::Measure() {
  RecordKill();
  RecordChaos();
  Phase("metrics", result_.num_units);
  std::vector<EstimatedRegistration> estimates;
  if (!LoadEstimates(&estimates)) return false;
  if (estimates.empty()) {
    return FailedWith("metrics", "no unit holds a calibration (every node reported a failure)");
  }
  // Where the model truly stands, in the frame the nodes' table_from_model refers to.
  result_.metric_options.true_table_from_model =
      TruePoseMode() ? Rigid3d::Identity() : inputs_.model_from_table.Inverse();
  CollectSelfCalibration();
  // The baseline: the same units with their factory intrinsics at their true poses.
  std::vector<EstimatedRegistration> baseline;
  for (const EstimatedRegistration& e : estimates) {
    const UnitSpec* unit = inputs_.site.FindUnit(e.unit_id);
    auto factory = inputs_.factory_paths.find(e.unit_id);
    if (!unit || factory == inputs_.factory_paths.end()) continue;
    Expected<UnitCalibration> held = LoadUnitCalibration(factory->second);
    if (!held.ok()) continue;  // the node read it at start; a later failure leaves no baseline
    baseline.push_back({e.unit_id, held->projector, unit->projector.table_from_projector,
                        result_.metric_options.true_table_from_model});
  }
  if (baseline.size() != estimates.size()) baseline.clear();
  // The metric and the pictures run on a worker while the children stay watched.
  struct Work {
    std::optional<RegistrationReport> report;
    std::optional<RegistrationReport> baseline;
    cv::Mat top, heatmap;
    double scale_mm = 0;
    std::string error;
    std::optional<ModelPlacementError> placement;
    bool true_placement = false;  // measured with the true model placement (none was found)
  };
  // The model's placement against the truth, when the nodes found it (structured light).
  const bool model_placement = !TruePoseMode() && units_have_model_;
  const Eigen::Vector3d model_centre = inputs_.model_from_table * scene_.Bounds().center();
  const RegistrationMetricOptions metric_options = result_.metric_options;
  const int width = options_.image_width_px;
  std::future<Work> future =
      std::async(std::launch::async,
                 [this, estimates, baseline, metric_options, width, model_placement, model_centre,
                  no_placement = !TruePoseMode() && !units_have_model_]() mutable -> Work {
                   Work work;
                   Expected<std::unique_ptr<World>> world = World::Create(inputs_.site, scene_);
                   if (!world.ok()) {
                     work.error = world.status().ToString();
                     return work;
                   }
                   if (no_placement) {
                     // The nodes found no placement of the model (a flat scene whose outline they
                     // do not see whole): the calibration is measured with the TRUE placement
                     // expressed in their table frame (related to the true one through table
                     // pixels), and the report says so (calibration.placement).
                     Expected<ModelPlacementError> frames = MeasureModelPlacement(
                         **world, estimates, metric_options.true_table_from_model, model_centre);
                     if (frames.ok()) {
                       for (EstimatedRegistration& e : estimates) {
                         e.table_from_model = frames->true_table_from_estimated_table.Inverse() *
                                              metric_options.true_table_from_model;
                       }
                       work.true_placement = true;
                     }
                   }
                   Expected<RegistrationReport> report =
                       MeasureRegistration(**world, estimates, metric_options);
                   if (!report.ok()) {
                     work.error = report.status().ToString();
                     return work;
                   }
                   work.report = std::move(*report);
                   if (!baseline.empty()) {
                     RegistrationMetricOptions o = metric_options;
                     o.keep_samples = false;
                     Expected<RegistrationReport> b = MeasureRegistration(**world, baseline, o);
                     if (b.ok()) work.baseline = std::move(*b);
                   }
                   if (model_placement) {
                     Expected<ModelPlacementError> placement = MeasureModelPlacement(
                         **world, estimates, metric_options.true_table_from_model, model_centre);
                     if (placement.ok()) work.placement = *placement;
                   }
                   if (Expected<cv::Mat> top = TopViewWhite(world->get(), width); top.ok()) {
                     work.top = *top;
                   }
                   work.scale_mm = std::max(1e-3, work.report->site.all.p99_mm);
                   if (Expected<cv::Mat> heat = RegistrationHeatmap(
                           **world, estimates, metric_options, width, work.scale_mm);
                       heat.ok()) {
                     work.heatmap = *heat;
                   }
                   return work;
                 });
  const auto ready = [&] {
    return future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
  };
  const WaitOutcome outcome =
      supervisor_.WaitUntil(ready, options_.timings.work_limit, stop_, Handler());
  if (outcome != WaitOutcome::kDone) {
    future.wait();
    return Failed("metrics", outcome, "", nullptr);
  }
  Work work = future.get();
  if (!work.error.empty()) return FailedWith("metrics", "registration metric: " + work.error);
  result_.registration = std::move(work.report);
  if (work.baseline) {
    result_.baseline_rms_mm = work.baseline->site.all.rms_mm;
    result_.baseline_p99_mm = work.baseline->site.all.p99_mm;
  }
  result_.measured_with_true_placement = work.true_placement;
  if (work.placement) {
    result_.model_offset_measured = true;
    result_.model_offset_mm = work.placement->offset_mm;
    result_.model_offset_deg = work.placement->offset_deg;
  }
  result_.heatmap_scale_mm = work.scale_mm;
  const fs::path dir(options_.out_dir);
  // A picture that cannot be written is left out of the report, with the reason logged.
  if (!work.top.empty()) {
    const Status written = io::WritePngFile((dir / "top_white.png").string(), work.top);
    if (written.ok()) {
      result_.top_white_png = "top_white.png";
    } else {
      ST_LOG(kWarning) << written.ToString();
    }
  }
  if (!work.heatmap.empty()) {
    const Status written =
        io::WritePngFile((dir / "registration_error_top.png").string(), work.heatmap);
    if (written.ok()) {
      result_.heatmap_png = "registration_error_top.png";
    } else {
      ST_LOG(kWarning) << written.ToString();
    }
  }
  progress_.End();
  return true;
}

void LabRun::CollectSelfCalibration() {
  json& sc = result_.self_calibration;
  sc = json::object();
  for (const auto& [id, line] : lines_.calibrated) {
    if (line.report.empty()) continue;
    Expected<std::string> text = ReadInputFile(line.report, size_t{16} << 20, "16 MiB");
    if (!text.ok()) continue;
    json parsed = json::parse(*text, nullptr, false);
    if (!parsed.is_discarded() && parsed.is_object()) sc["runner_report"] = parsed;
  }
  // The runner's MPCDI export, read back with the same reader as the files of other tools.
  for (const auto& [id, line] : lines_.calibrated) {
    const std::string& path = line.mpcdi;
    if (path.empty()) continue;
    Expected<MpcdiSite> site = ReadMpcdi(path);
    if (!site.ok()) {
      sc["mpcdi"] = {{"path", path}, {"error", site.status().message()}};
      continue;
    }
    json regions = json::array();
    for (const MpcdiRegion& region : site->regions) {
      int samples = 0, hits = 0;
      if (region.warp) {
        samples = static_cast<int>(region.warp->samples.size());
        for (const Eigen::Vector3f& v : region.warp->samples) hits += v.allFinite();
      }
      regions.push_back({{"id", region.id},
                         {"resolution_px", {region.x_resolution_px, region.y_resolution_px}},
                         {"warp_samples", samples},
                         {"warp_samples_on_surface", hits},
                         {"alpha", region.alpha.has_value()},
                         {"alpha_mean", AlphaMean(region)}});
    }
    sc["mpcdi"] = {{"path", path}, {"profile", site->profile}, {"regions", regions}};
  }
  json per_unit = json::object();
  double slowest = 0.0;
  double messages = 0, bytes = 0;
  for (const auto& [id, line] : lines_.calibrated) {
    json u = {{"compute_s", line.compute_s},
              {"messages_sent", line.messages_sent},
              {"messages_received", line.messages_received},
              {"bytes_sent", line.bytes_sent},
              {"bytes_received", line.bytes_received},
              {"capture_latency_ms", line.capture_latency_ms},
              {"capture_settle_ms", line.capture_settle_ms},
              {"captures", line.captures},
              {"captures_stale", line.captures_stale},
              {"captures_repeated", line.captures_repeated}};
    slowest = std::max(slowest, line.compute_s);
    messages += static_cast<double>(line.messages_sent + line.messages_received);
    bytes += static_cast<double>(line.bytes_sent + line.bytes_received);
    per_unit[std::to_string(id)] = u;
  }
  sc["per_unit"] = per_unit;
  if (!lines_.verification.empty()) {
    json checks = json::object();
    for (const auto& [id, line] : lines_.verification)
      checks[std::to_string(id)] = report::ToJson(line);
    sc["verification"] = checks;
  }
  bool round_ran = false;
  for (const auto& [id, line] : lines_.calibrated) round_ran |= line.round != 0;
  sc["round_ran"] = round_ran;
  sc["compute_time_s"] = slowest;
  if (!lines_.calibrated.empty()) {
    sc["messages_per_node"] = messages / lines_.calibrated.size();
    sc["bytes_per_node"] = bytes / lines_.calibrated.size();
  }
}

void LabRun::CollectRender() {
  if (lines_.render_summary.empty()) return;
  std::vector<double> p50, p99, floor, first;
  json units = json::object();
  for (const auto& [id, line] : lines_.render_summary) {
    units[std::to_string(id)] = report::ToJson(line);
    if (line.frames > 0) {
      p50.push_back(line.frame_ms_p50);
      p99.push_back(line.frame_ms_p99);
      floor.push_back(line.floor_ms);
      first.push_back(line.first_frame_ms);
    }
  }
  result_.render["units"] = units;
  if (p50.empty()) return;
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  result_.render["frame_ms_p50"] = median(p50);
  result_.render["frame_ms_p99"] = *std::max_element(p99.begin(), p99.end());
  result_.render["floor_ms"] = median(floor);
  result_.render["first_frame_ms_max"] = *std::max_element(first.begin(), first.end());
  result_.render["context"] = lines_.render_summary.begin()->second.context;
}

// Every calibrated unit's exported calibration, loaded as the metric takes it; false (failure
// recorded) when one does not load or holds no pose.
bool LabRun::LoadEstimates(std::vector<EstimatedRegistration>* estimates) {
  std::set<std::string> sources;
  for (const auto& [id, why] : lines_.calibration_failed) result_.unit_failures[id] = why;
  for (const UnitSpec& unit : inputs_.site.units) {
    if (!lines_.calibrated.count(unit.id)) continue;  // failed: named in the report
    const std::string path = lines_.calibrated.at(unit.id).json;
    Expected<UnitCalibration> calibration = LoadUnitCalibration(path);
    if (!calibration.ok()) {
      return FailedWith("metrics", "unit " + std::to_string(unit.id) +
                                       ": cannot load its exported calibration: " +
                                       calibration.status().ToString());
    }
    if (!calibration->table_from_projector) {
      return FailedWith("metrics", path + ": no table_from_projector (unit not registered)");
    }
    LabUnitResult& unit_result = result_.units[unit.id];
    unit_result.source = calibration->source;
    unit_result.json_path = RelativeToOut(path);
    const std::string& yaml = lines_.calibrated.at(unit.id).yaml;
    unit_result.yaml_path = RelativeToOut(yaml);
    // No OpenCV YAML is written when the model was not found (its R, T are model ->
    // projector); the report says so through the runner's report.
    if (!yaml.empty() && !fs::exists(yaml)) {
      return FailedWith("metrics", "unit " + std::to_string(unit.id) + ": its OpenCV YAML " + yaml +
                                       " is missing");
    }
    sources.insert(calibration->source);
    if (calibration->table_from_model) units_have_model_ = true;
    // The projector's response as its own camera measured it, against the world's.
    if (calibration->projector_response) RecordResponse(unit, *calibration->projector_response);
    estimates->push_back({unit.id, calibration->projector, *calibration->table_from_projector,
                          calibration->table_from_model.value_or(Rigid3d::Identity())});
  }
  result_.calibration_source = sources.size() == 1 ? *sources.begin() : "mixed";
  return true;
}

// A unit's projector response as its own camera measured it, against the world's.
void LabRun::RecordResponse(const UnitSpec& unit, const ProjectorResponseRecord& r) {
  json response = {{"gamma", r.gamma},
                   {"true_gamma", unit.projector.gamma},
                   {"gamma_error", r.gamma - unit.projector.gamma},
                   {"true_black_level", unit.projector.black_level}};
  if (r.black_level >= 0) {
    response["black_level"] = r.black_level;
    response["black_level_error"] = r.black_level - unit.projector.black_level;
  }
  if (!result_.photometric.is_object()) result_.photometric = json::object();
  json& p = result_.photometric;
  p["response"][std::to_string(unit.id)] = response;
  p["gamma_error"] =
      std::max(p.value("gamma_error", 0.0), std::abs(r.gamma - unit.projector.gamma));
  if (r.black_level >= 0) {
    p["black_level_error"] = std::max(p.value("black_level_error", 0.0),
                                      std::abs(r.black_level - unit.projector.black_level));
  }
}

}  // namespace sandtable::sim::lab_internal
