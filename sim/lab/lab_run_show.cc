// The lab run's show and blend phases (lab_run_internal.h): test patterns, the world's top
// views, the grid coincidence and the photometric measure.
#include "sim/lab/lab_run_internal.h"

#include <thread>

#include "common/estimation/footprint.h"
#include "sim/lab/lab_pictures.h"

namespace sandtable::sim::lab_internal {

Status LabRun::SetPattern(const std::string& pattern) {
  wire::Envelope request;
  request.mutable_test_pattern_request()->set_all_nodes(true);
  request.mutable_test_pattern_request()->set_pattern(pattern);
  Expected<wire::Envelope> reply =
      Call(lines_.coordinator_requests, std::move(request), wire::Envelope::kTestPatternReply,
           options_.timings.request_timeout);
  if (!reply.ok()) return reply.status();
  if (!reply->test_pattern_reply().accepted()) {
    return InvalidArgumentError("pattern refused: " + reply->test_pattern_reply().reason());
  }
  return OkStatus();
}

Expected<TopView> LabRun::TopViewOf(const std::vector<NodeId>& lit) {
  // The nodes said they show their frames; a projector with an input lag puts them on the
  // table that much later (sim/site/device_timing.h).
  double lag_s = 0.0;
  for (const UnitSpec& unit : inputs_.site.units) {
    if (unit.timing.lag_frames > 0) {
      lag_s = std::max(lag_s, (unit.timing.lag_frames + 1) / unit.timing.refresh_hz);
    }
  }
  if (lag_s > 0) std::this_thread::sleep_for(std::chrono::duration<double>(lag_s));
  wire::Envelope request;
  for (NodeId id : lit) request.mutable_top_view_request()->add_projector_ids(id);
  request.mutable_top_view_request()->set_width_px(
      static_cast<uint32_t>(options_.grid_view_width_px));
  Expected<wire::Envelope> reply =
      Call(lines_.world_endpoint, std::move(request), wire::Envelope::kTopViewReply,
           options_.timings.world_render_timeout);
  if (!reply.ok()) return reply.status();
  const wire::TopViewReply& r = reply->top_view_reply();
  if (!r.ok()) return UnavailableError(r.message());
  TopView view;
  view.luminance =
      cv::Mat(static_cast<int>(r.height_px()), static_cast<int>(r.width_px()), CV_32FC1);
  if (r.luminance().size() != view.luminance.total() * sizeof(float)) {
    return ParseError("top view: the luminance does not fill the image");
  }
  std::memcpy(view.luminance.data, r.luminance().data(), r.luminance().size());
  view.area_min_m = Eigen::Vector2d(r.area_min_in_table_m().x(), r.area_min_in_table_m().y());
  view.area_max_m = Eigen::Vector2d(r.area_max_in_table_m().x(), r.area_max_in_table_m().y());
  return view;
}

cv::Mat LabRun::TableMask(const std::map<NodeId, TopView>& views) const {
  if (views.empty()) return cv::Mat();
  const TopView& v = views.begin()->second;
  Expected<std::unique_ptr<RayCaster>> caster =
      RayCaster::Create(std::make_shared<const Scene>(scene_));
  if (!caster.ok()) return cv::Mat();
  cv::Mat mask(v.luminance.size(), CV_8UC1, cv::Scalar(0));
  const Eigen::Vector2d span = v.area_max_m - v.area_min_m;
  const double top_m = scene_.Bounds().max().z() + 1.0;
  for (int y = 0; y < mask.rows; ++y) {
    for (int x = 0; x < mask.cols; ++x) {
      const Eigen::Vector2d xy =
          v.area_min_m + Eigen::Vector2d((x + 0.5) / mask.cols * span.x(),
                                         (1.0 - (y + 0.5) / mask.rows) * span.y());
      const std::optional<RayHit> hit =
          (*caster)->Intersect(Eigen::Vector3d(xy.x(), xy.y(), top_m), -Eigen::Vector3d::UnitZ());
      if (hit && std::abs(hit->point_in_table_m.z()) < 1e-3) mask.at<uint8_t>(y, x) = 255;
    }
  }
  return mask;
}

bool LabRun::WaitForPattern(const std::string& pattern) {
  const auto done = [&] {
    for (const auto& [id, line] : lines_.calibrated) {
      auto it = lines_.render_pattern.find(id);
      if (it == lines_.render_pattern.end() || it->second != pattern) return false;
    }
    return true;
  };
  const WaitOutcome outcome =
      supervisor_.WaitUntil(done, options_.timings.pattern_wait, stop_, Handler());
  if (outcome == WaitOutcome::kDone) return true;
  return Failed("show", outcome, "not every calibrated node showed the pattern '" + pattern + "'",
                nullptr);
}

bool LabRun::Show() {
  if (options_.render == "off" || lines_.calibrated.empty()) return true;
  if (!lines_.render_unavailable.empty()) {
    // A node without GL runs without a show: the run goes on, the report says why.
    const auto& [id, why] = *lines_.render_unavailable.begin();
    result_.render["error"] = "node-" + std::to_string(id) + " cannot render: " + why;
    return true;
  }
  Phase("show", 0);
  const fs::path dir(options_.out_dir);
  // 1. The table grid on every projector, seen from above one projector at a time.
  std::vector<NodeId> units;
  for (const auto& [id, line] : lines_.calibrated) units.push_back(id);
  if (!ShowGrid(units)) return false;
  Status set;
  // 2. The show: the lab's personnel tracks play for show_s.
  set = SetPattern("none");
  if (!set.ok()) return FailedWith("show", "test pattern: " + set.ToString());
  if (!WaitForPattern("none")) return false;
  wire::Envelope play;
  play.mutable_play();
  Expected<wire::Envelope> played =
      Call(lines_.coordinator_requests, std::move(play), wire::Envelope::kTimelineReply,
           options_.timings.request_timeout);
  if (!played.ok() || !played->timeline_reply().accepted()) {
    return FailedWith("show", "timeline play: " + (played.ok() ? played->timeline_reply().reason()
                                                               : played.status().ToString()));
  }
  const WaitOutcome outcome = supervisor_.Watch(ToMs(options_.show_s), stop_, Handler());
  if (outcome != WaitOutcome::kDone) return Failed("show", outcome, "", nullptr);
  TopViews shown;
  if (!Watched<TopViews>(
          "show",
          [this] {
            TopViews v;
            Expected<TopView> all = TopViewOf({});
            if (all.ok()) {
              v.all = std::move(*all);
            } else {
              v.error = all.status().ToString();
            }
            return v;
          },
          &shown)) {
    return false;
  }
  if (shown.all &&
      io::WritePngFile((dir / "show_top.png").string(), LuminancePicture(shown.all->luminance))
          .ok()) {
    result_.render["show_top_png"] = "show_top.png";
  }
  wire::Envelope pause;
  pause.mutable_pause();
  (void)Call(lines_.coordinator_requests, std::move(pause), wire::Envelope::kTimelineReply,
             options_.timings.request_timeout);
  std::map<NodeId, std::string> logs;
  for (NodeId id : units) {
    logs[id] = (dir / "logs" / ("render-" + std::to_string(id) + ".csv")).string();
  }
  // The logs are flushed once a second: wait for the last frames of the show.
  (void)supervisor_.Watch(options_.timings.render_log_flush, stop_, Handler());
  std::map<NodeId, int64_t> offsets_ns;
  for (NodeId id : units) {
    offsets_ns[id] = static_cast<int64_t>(ClockOffsetS(id) * 1e9);
  }
  Expected<TimelineSkew> skew = MeasureTimelineSkew(logs, offsets_ns);
  result_.render["timeline_skew"] =
      skew.ok() ? skew->ToJson() : nlohmann::json{{"error", skew.status().message()}};
  if (skew.ok()) result_.render["timeline_skew_ms_p99"] = skew->p99_ms;
  progress_.End();
  return true;
}

Expected<wire::GroundTruthReply> LabRun::GroundTruth(NodeId projector,
                                                     const std::vector<Eigen::Vector3d>& points) {
  wire::Envelope request;
  wire::GroundTruthRequest* r = request.mutable_ground_truth_request();
  r->set_projector_id(projector);
  for (const Eigen::Vector3d& p : points) {
    wire::Vector3* v = r->add_points_in_table_m();
    v->set_x(p.x());
    v->set_y(p.y());
    v->set_z(p.z());
  }
  Expected<wire::Envelope> reply =
      Call(lines_.world_endpoint, std::move(request), wire::Envelope::kGroundTruthReply,
           options_.timings.world_render_timeout);
  if (!reply.ok()) return reply.status();
  const wire::GroundTruthReply& g = reply->ground_truth_reply();
  if (!g.ok() || g.samples_size() != static_cast<int>(points.size())) {
    return UnavailableError("ground truth: " + g.message());
  }
  return g;
}

Expected<std::vector<SampleTruth>> LabRun::TruthSamples(
    NodeId projector, const std::vector<Eigen::Vector3d>& points) {
  Expected<wire::GroundTruthReply> g = GroundTruth(projector, points);
  if (!g.ok()) return g.status();
  std::vector<SampleTruth> out(points.size());
  for (int i = 0; i < g->samples_size(); ++i) {
    const wire::GroundTruthSample& sample = g->samples(i);
    out[i].projectable = sample.projectable();
    out[i].visible = sample.visible();
    out[i].pixel_px = Eigen::Vector2d(sample.projector_px().x(), sample.projector_px().y());
  }
  return out;
}

Expected<std::vector<double>> LabRun::TruthLuminance(NodeId projector,
                                                     const std::vector<Eigen::Vector3d>& points) {
  Expected<wire::GroundTruthReply> g = GroundTruth(projector, points);
  if (!g.ok()) return g.status();
  std::vector<double> out(points.size(), 0.0);
  for (int i = 0; i < g->samples_size(); ++i) {
    if (g->samples(i).visible()) out[i] = g->samples(i).luminance_cd_per_m2();
  }
  return out;
}

Expected<json> LabRun::PlaceTableSteps(const StepStats& steps, const TopView& view,
                                       double bound_pct) {
  const Eigen::Vector2d span = view.area_max_m - view.area_min_m;
  auto at = [&](double x, double y) {
    return Eigen::Vector3d(view.area_min_m.x() + (x + 0.5) / view.luminance.cols * span.x(),
                           view.area_min_m.y() + (1.0 - (y + 0.5) / view.luminance.rows) * span.y(),
                           0.0);
  };
  std::vector<ProjectorSize> projectors;
  for (const UnitSpec& unit : inputs_.site.units) {
    if (!lines_.calibrated.count(unit.id)) continue;
    projectors.push_back({unit.id, unit.projector.model.width_px, unit.projector.model.height_px});
  }
  Expected<StepPlaces> places =
      PlaceSteps(steps, bound_pct, at, projectors,
                 [this](NodeId id, const std::vector<Eigen::Vector3d>& points) {
                   return TruthSamples(id, points);
                 });
  if (!places.ok()) return places.status();
  return places->ToJson(bound_pct);
}

bool LabRun::Blend() {
  if (options_.render == "off" || options_.blend == "off" || lines_.calibrated.empty() ||
      !lines_.render_unavailable.empty()) {
    return true;
  }
  Phase("blend", static_cast<int>(lines_.calibrated.size()));
  const fs::path dir(options_.out_dir);
  // 1. Every calibrated node has shown a blend and none has changed it for settle.
  json unsettled = json::object();
  if (!WaitForBlendSettled(&unsettled)) return false;
  if (lines_.blend.empty()) return FailedWith("blend", "no node showed a blend within blend_wait");
  // 2. Raw white, then white through the full pipeline (the blend), seen from above.
  struct Views {
    std::optional<TopView> view;
    std::string error;
  };
  auto top = [this](const std::string& pattern, Views* out) {
    Status set = SetPattern(pattern);
    if (!set.ok()) return FailedWith("blend", "test pattern: " + set.ToString());
    if (!WaitForPattern(pattern)) return false;
    return Watched<Views>(
        "blend",
        [this] {
          Views v;
          Expected<TopView> all = TopViewOf({});
          if (all.ok()) {
            v.view = std::move(*all);
          } else {
            v.error = all.status().ToString();
          }
          return v;
        },
        out);
  };
  Views before, after, black;
  if (!top("raw-white", &before) || !top("black", &black) || !top("white", &after)) {
    return false;
  }
  if (!before.view || !after.view || !black.view) {
    return FailedWith("blend", "top view: " + before.error + black.error + after.error);
  }
  // 3. Walls and roofs: the truth at lattice points, with white still shown.
  BlendMeasure measured;
  if (!Watched<BlendMeasure>(
          "blend", [&] { return MeasureBlend(*before.view, *after.view, *black.view); },
          &measured)) {
    return false;
  }
  if (!measured.error.empty()) return FailedWith("blend", "measure: " + measured.error);
  json& p = measured.photometric;
  // The nodes' figures: level, cast and compose times, bytes, neighbours.
  json nodes = json::object();
  double cast_ms_max = 0.0, bytes_max = 0.0;
  for (const auto& [id, line] : lines_.blend) {
    nodes[std::to_string(id)] = report::ToJson(line);
    cast_ms_max = std::max(cast_ms_max, line.cast_ms);
    bytes_max = std::max(bytes_max, static_cast<double>(line.bytes_sent + line.bytes_received));
    p["level_per_m2"] = line.level_per_m2;
  }
  p["nodes"] = nodes;
  p["blend_cast_ms_max"] = cast_ms_max;
  p["bytes_per_node_max"] = bytes_max;
  // Pictures.
  auto write = [&](const std::string& name, const cv::Mat& image, const std::string& key) {
    if (io::WritePngFile((dir / name).string(), image).ok()) p["pictures"][key] = name;
  };
  write("blend_before_top.png", LuminancePicture(before.view->luminance), "before");
  write("blend_after_top.png", LuminancePicture(after.view->luminance), "after");
  std::vector<PictureFootprint> footprints;
  for (const UnitSpec& unit : inputs_.site.units) {
    if (!lines_.calibrated.count(unit.id)) continue;
    footprints.push_back(
        {static_cast<int>(unit.id),
         TableFootprint(unit.projector.model, unit.projector.table_from_projector)});
  }
  write("blend_steps_over_1pct.png",
        StepsPicture(LuminancePicture(after.view->luminance), measured.over,
                     {after.view->area_min_m, after.view->area_max_m}, footprints),
        "steps_over_1pct");
  for (const auto& [id, line] : lines_.blend) {
    const fs::path alpha = dir / "calibration" / ("blend-" + std::to_string(id) + ".png");
    if (fs::exists(alpha)) {
      p["pictures"]["alpha"][std::to_string(id)] = fs::relative(alpha, dir).string();
    }
  }
  RecordJoinReblend();
  if (!unsettled.empty()) p["unsettled"] = unsettled;
  result_.photometric = p;
  Status set = SetPattern("none");
  if (!set.ok()) return FailedWith("blend", "test pattern: " + set.ToString());
  progress_.End();
  return true;
}

// Settled: every node's last mask holds the field of every unit it overlaps (none is
// `waiting_for` one), and no node has shown a new one for blend_settle. A node still waiting
// after blend_wait is measured as it is and named in `unsettled`. Only units that calibrated
// count: one that failed (or was killed) never shares a field.
bool LabRun::WaitForBlendSettled(json* unsettled) {
  const milliseconds settle = options_.timings.blend_settle;
  auto waiting = [&](const report::BlendShown& line) {
    for (NodeId unit : line.waiting_for) {
      if (lines_.calibrated.count(unit)) return true;
    }
    return false;
  };
  const WaitOutcome settled = supervisor_.WaitUntil(
      [&] {
        progress_.Update(static_cast<int>(lines_.blend.size()));
        for (const auto& [id, line] : lines_.calibrated) {
          auto it = lines_.blend.find(id);
          if (it == lines_.blend.end() || waiting(it->second)) return false;
        }
        return std::chrono::steady_clock::now() - lines_.last_blend_line > settle;
      },
      options_.timings.blend_wait, stop_, Handler());
  if (settled != WaitOutcome::kDone && settled != WaitOutcome::kDeadline) {
    return Failed("blend", settled, "", nullptr);
  }
  for (const auto& [id, line] : lines_.calibrated) {
    auto it = lines_.blend.find(id);
    if (it == lines_.blend.end()) {
      (*unsettled)[std::to_string(id)] = "no blend shown";
    } else if (waiting(it->second)) {
      (*unsettled)[std::to_string(id)] = it->second.waiting_for;
    }
  }
  return true;
}

// The photometric measure of a blend (docs/blend.md): the steps per surface kind from the
// world's top views (raw white `b`, white through the blend `a`, every projector black) and, on
// walls and roofs, from the truth at lattice points; the uniformity.
LabRun::BlendMeasure LabRun::MeasureBlend(const TopView& b, const TopView& a,
                                          const TopView& black) {
  BlendMeasure m;
  const auto start = std::chrono::steady_clock::now();
  auto scene = std::make_shared<const Scene>(scene_);
  Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(scene);
  if (!caster.ok()) {
    m.error = caster.status().ToString();
    return m;
  }
  const FaceGroups faces = GroupFaces(*scene);
  std::vector<StraddleTest::Projector> projectors;
  for (const UnitSpec& unit : inputs_.site.units) {
    if (!lines_.calibrated.count(unit.id)) continue;
    projectors.push_back({unit.projector.model, unit.projector.table_from_projector.Inverse()});
  }
  const StraddleTest straddle(projectors, **caster, faces);
  const cv::Mat ids =
      TopViewFaceIds(**caster, faces, a.area_min_m, a.area_max_m, a.luminance.size());
  const cv::Mat straddled =
      TopViewStraddled(**caster, straddle, a.area_min_m, a.area_max_m, a.luminance.size());
  const double lit = kLitAmbientFactor * inputs_.site.ambient_luminance_nits;
  const int spacing_px =
      std::max(1, static_cast<int>(std::lround(kStepSpacing_m * 1e3 / a.mm_per_px())));
  json p = json::object();
  const StepStats table = MeasureImageSteps(a.luminance, ids, faces, SurfaceKind::kTable,
                                            spacing_px, lit, &m.over, straddled);
  const StepStats roof_top = MeasureImageSteps(a.luminance, ids, faces, SurfaceKind::kRoof,
                                               spacing_px, lit, nullptr, straddled);
  const StepStats table_before = MeasureImageSteps(b.luminance, ids, faces, SurfaceKind::kTable,
                                                   spacing_px, lit, nullptr, straddled);
  // Every projector black: where footprints overlap their black levels add up (on top
  // of the site's ambient light). Measured on the table the blended white lights (the
  // display area; outside every footprint nothing can be lifted), every pixel of it.
  cv::Mat black_ids = ids.clone();
  black_ids.setTo(-1, a.luminance <= lit);
  const StepStats black_table = MeasureImageSteps(
      black.luminance, black_ids, faces, SurfaceKind::kTable, spacing_px, 0.0, nullptr, straddled);
  p["black"] = black_table.ToJson();
  p["black_step_pct"] = black_table.max_pct;
  p["black_match"] = options_.black_match == "on";
  p["table"] = table.ToJson();
  Expected<json> places = PlaceTableSteps(table, a, kTableStepBoundPct);
  if (!places.ok()) {
    m.error = places.status().ToString();
    return m;
  }
  p["table"]["over_bound"] = *places;
  p["roofs_from_above"] = roof_top.ToJson();
  p["table_unblended"] = table_before.ToJson();
  p["uniformity_min_over_max"] = TableUniformity(a.luminance, ids, faces, lit, straddled);
  p["uniformity_unblended"] = TableUniformity(b.luminance, ids, faces, lit, straddled);
  for (SurfaceKind kind : {SurfaceKind::kWall, SurfaceKind::kRoof}) {
    const SurfaceLattice lattice = SampleFaces(*scene, faces, kind, kStepSpacing_m);
    std::vector<double> l(lattice.points_in_table_m.size(), inputs_.site.ambient_luminance_nits);
    for (const auto& [id, line] : lines_.calibrated) {
      Expected<std::vector<double>> t = TruthLuminance(id, lattice.points_in_table_m);
      if (!t.ok()) {
        m.error = t.status().ToString();
        return m;
      }
      for (size_t i = 0; i < l.size(); ++i) l[i] += (*t)[i];
    }
    const StepStats steps = MeasureSampleSteps(l, lattice, lit, &straddle);
    p[kind == SurfaceKind::kWall ? "walls" : "roofs"] = steps.ToJson();
  }
  p["max_step_pct_per_5mm"] = {
      {"table", table.max_pct}, {"walls", p["walls"]["max_pct"]}, {"roofs", p["roofs"]["max_pct"]}};
  p["p99_step_pct_per_5mm"] = {
      {"table", table.p99_pct}, {"walls", p["walls"]["p99_pct"]}, {"roofs", p["roofs"]["p99_pct"]}};
  p["measure_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  m.photometric = p;
  return m;
}

// A late unit's join: from its calibrated line to each neighbour's first mask with it.
void LabRun::RecordJoinReblend() {
  if (options_.join_late < 0) return;
  const NodeId late = static_cast<NodeId>(options_.join_late);
  auto calibrated_at = lines_.calibrated_at.find(late);
  if (calibrated_at == lines_.calibrated_at.end()) return;
  const int64_t join_calibrated_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(calibrated_at->second.time_since_epoch())
          .count();
  json join = json::object();
  double join_max_ms = 0.0;
  for (const report::BlendShown& line : lines_.blended) {
    const NodeId id = line.id;
    if (id == late || join.contains(std::to_string(id))) continue;
    const std::vector<NodeId>& n = line.neighbours;
    if (std::find(n.begin(), n.end(), late) == n.end()) continue;
    const double ms = (line.shown_ns - join_calibrated_ns) * 1e-6;
    join[std::to_string(id)] = ms;
    join_max_ms = std::max(join_max_ms, ms);
  }
  if (!join.empty()) {
    result_.live["join_reblend_ms"] = join_max_ms;
    result_.live["join_reblend"] = join;
  }
}

// The table grid on every projector, seen from above one projector at a time: the grid
// coincidence (render_metrics.h) and the pictures.
bool LabRun::ShowGrid(const std::vector<NodeId>& units) {
  const fs::path dir(options_.out_dir);
  Status set = SetPattern("grid");
  if (!set.ok()) return FailedWith("show", "test pattern: " + set.ToString());
  if (!WaitForPattern("grid")) return false;
  TopViews views;
  if (!Watched<TopViews>(
          "show",
          [this, units] {
            TopViews v;
            for (NodeId id : units) {
              Expected<TopView> view = TopViewOf({id});
              if (!view.ok()) {
                v.error = view.status().ToString();
                return v;
              }
              v.each[id] = std::move(*view);
            }
            if (Expected<TopView> all = TopViewOf({}); all.ok()) v.all = std::move(*all);
            return v;
          },
          &views)) {
    return false;
  }
  if (!views.error.empty()) return FailedWith("show", "top view: " + views.error);
  Expected<GridCoincidence> grid = MeasureGridCoincidence(views.each, TableMask(views.each));
  result_.render["grid"] =
      grid.ok() ? grid->ToJson() : nlohmann::json{{"error", grid.status().message()}};
  // Each projector's output alone, as it lands on the table (the report's per-projector view).
  for (const auto& [id, view] : views.each) {
    const std::string png = "show_grid_top_unit-" + std::to_string(id) + ".png";
    if (io::WritePngFile((dir / png).string(), LuminancePicture(view.luminance)).ok()) {
      result_.render["unit_grid_top_png"][std::to_string(id)] = png;
    }
  }
  if (views.all) {
    if (io::WritePngFile((dir / "show_grid_top.png").string(),
                         LuminancePicture(views.all->luminance))
            .ok()) {
      result_.render["grid_top_png"] = "show_grid_top.png";
    }
  }
  return true;
}

}  // namespace sandtable::sim::lab_internal
