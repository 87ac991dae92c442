// The lab run's faults (lab_run_internal.h): a unit that joins late, a unit killed or stopped,
// the coordinator killed and restarted, the chaos figures, and the hold they happen in.
#include "sim/lab/lab_run_internal.h"

namespace sandtable::sim::lab_internal {

bool LabRun::Join() {
  if (options_.join_late < 0) return true;
  Phase("join", 1);
  const NodeId late = static_cast<NodeId>(options_.join_late);
  // A calibrated site is also blended: the held units' masks settle first (a blend line from
  // each, then none for blend_settle), so the frames counted below are the join's own.
  if (options_.render != "off" && options_.blend != "off") {
    const WaitOutcome blended = supervisor_.WaitUntil(
        [&] {
          for (const auto& [id, line] : lines_.calibrated) {
            if (!lines_.blend.count(id) && !lines_.render_unavailable.count(id)) return false;
          }
          return std::chrono::steady_clock::now() - lines_.last_blend_line >
                 options_.timings.blend_settle;
        },
        options_.timings.blend_wait, stop_, Handler());
    if (blended != WaitOutcome::kDone && blended != WaitOutcome::kDeadline) {
      return Failed("join", blended, "", nullptr);
    }
  }
  const std::map<NodeId, report::Calibrated> before = lines_.calibrated;
  const auto t0 = std::chrono::steady_clock::now();
  const int64_t t0_ms = SystemMs();
  const UnitSpec* spec = inputs_.site.FindUnit(late);
  if (!spec) {
    return FailedWith("join", "--join-late " + std::to_string(late) + ": the site has no unit " +
                                  std::to_string(late));
  }
  if (!StartNode(*spec)) return false;
  if (!Wait(
          "join",
          [&] { return lines_.calibrated.count(late) || lines_.calibration_failed.count(late); },
          ToMs(options_.calibration_timeout_s), "the late sandtable-node reported no calibration",
          nullptr, [&] { return static_cast<int>(lines_.calibrated.count(late)); },
          [&] { return "node-" + std::to_string(late); })) {
    return false;
  }
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // The frames the join itself gave the others: up to the late unit's calibration (after it,
  // its neighbours re-blend with its field: live.join_reblend).
  const int64_t t1_ms = SystemMs();
  const WaitOutcome settled = supervisor_.Watch(options_.timings.join_settle, stop_, Handler());
  if (settled != WaitOutcome::kDone) return Failed("join", settled, "", nullptr);
  std::vector<NodeId> recalibrated;
  for (const auto& [id, line] : before) {
    if (lines_.calibrated.at(id).round != line.round) recalibrated.push_back(id);
  }
  // What every projector was given meanwhile, from the world's own record.
  std::map<NodeId, int> frames;
  std::map<NodeId, std::set<std::string>> distinct;
  std::map<NodeId, std::string> hash_before, hash_after;
  for (const UnitSpec& unit : inputs_.site.units) frames[unit.id] = 0;
  if (Expected<std::string> log = ReadInputFile(FrameLogPath(), size_t{256} << 20, "256 MiB");
      log.ok()) {
    std::istringstream lines(*log);
    for (std::string text; std::getline(lines, text);) {
      json line = json::parse(text, nullptr, false);
      if (line.is_discarded() || !line.is_object()) continue;
      const int64_t t = line.value("time_ms", int64_t{0});
      const NodeId p = line.value("projector", kInvalidNodeId);
      const std::string hash = line.value("hash", std::string());
      if (t < t0_ms) hash_before[p] = hash;
      if (t < t0_ms || t > t1_ms) continue;
      ++frames[p];
      distinct[p].insert(hash);
      hash_after[p] = hash;
    }
  }
  json frames_json = json::object();
  std::vector<NodeId> unchanged;
  for (const auto& [p, count] : frames) {
    frames_json[std::to_string(p)] = {
        {"frames_set", count},
        {"distinct", distinct[p].size()},
        // Back on the frame it showed before the join (or never given another).
        {"restored", count == 0 || (hash_before.count(p) && hash_after[p] == hash_before[p])}};
    if (p != late && count == 0) unchanged.push_back(p);
  }
  json join = {{"unit", late},
               {"wall_s", wall_s},
               {"joined", lines_.calibrated.count(late) > 0},
               {"others_recalibrated", recalibrated},
               {"frames_during_join", frames_json},
               {"units_showing_the_same_frame", unchanged}};
  if (lines_.calibrated.count(late)) {
    const std::string path = lines_.calibrated.at(late).join_report;
    if (!path.empty()) {
      Expected<std::string> text = ReadInputFile(path, size_t{16} << 20, "16 MiB");
      if (text.ok()) {
        json parsed = json::parse(*text, nullptr, false);
        if (!parsed.is_discarded()) join["report"] = parsed;
      }
    }
  } else {
    join["error"] = lines_.calibration_failed.at(late);
  }
  result_.join = join;
  progress_.End();
  return true;
}

void LabRun::MaybeKill() {
  const bool holding = hold_started_ != std::chrono::steady_clock::time_point{};
  if (options_.kill_unit < 0 || killed_ || (options_.kill_after_calibration && !holding)) return;
  const auto from = options_.kill_after_calibration ? hold_started_ : calibration_started_;
  if (std::chrono::steady_clock::now() - from < std::chrono::duration<double>(options_.kill_at_s)) {
    return;
  }
  const NodeId unit = static_cast<NodeId>(options_.kill_unit);
  for (const auto& child : supervisor_.children()) {
    if (child->name() != "node-" + std::to_string(unit)) continue;
    supervisor_.ExpectExit(child.get());
    intended_kills_.insert(child->name());
    kill_ns_ = std::chrono::duration_cast<std::chrono::nanoseconds>(
                   std::chrono::steady_clock::now().time_since_epoch())
                   .count();
    child->Signal(SIGKILL);
    killed_ = true;
    kill_at_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - from).count();
    killed_while_calibrating_ = !lines_.calibrated.count(unit);
    calibrated_at_kill_ = lines_.calibrated;
    if (killed_while_calibrating_) {
      lines_.calibration_failed[unit] = "unit " + std::to_string(unit) + ": killed by the lab " +
                                        std::to_string(kill_at_s_) +
                                        " s into the calibration (--kill-unit)";
    }
    ST_LOG(kWarning) << "lab: killed node-" << unit << " (--kill-unit)";
  }
}

void LabRun::MaybeAcceptEnrollment() {
  if (options_.enroll_unit < 0 || enroll_started_ == std::chrono::steady_clock::time_point{}) {
    return;
  }
  const NodeId unit = static_cast<NodeId>(options_.enroll_unit);
  const auto now = std::chrono::steady_clock::now();
  const double since_start = std::chrono::duration<double>(now - enroll_started_).count();
  if (enroll_accepted_) {
    if (lines_.nodes_ready.count(unit) && !result_.enrollment.contains("ready_after_s")) {
      result_.enrollment["ready_after_s"] = since_start;
    }
    return;
  }
  if (now < next_enroll_poll_) return;
  next_enroll_poll_ = now + options_.timings.reply_poll * 2;
  if (lines_.coordinator_requests.empty()) return;
  wire::Envelope list;
  list.mutable_enrollment_request();
  Expected<wire::Envelope> reply =
      Call(lines_.coordinator_requests, std::move(list), wire::Envelope::kEnrollmentReply,
           options_.timings.request_timeout);
  if (!reply.ok()) return;
  for (const wire::EnrollingUnit& asking : reply->enrollment_reply().units()) {
    if (asking.node_id() != unit || asking.state() != "pending") continue;
    if (result_.enrollment.is_null()) {
      result_.enrollment = {{"unit", unit},
                            {"fingerprint", asking.fingerprint()},
                            {"asked_after_s", since_start - asking.waiting_s()}};
    }
    wire::Envelope accept;
    accept.mutable_enrollment_request()->set_accept(asking.fingerprint());
    Expected<wire::Envelope> decided =
        Call(lines_.coordinator_requests, std::move(accept), wire::Envelope::kEnrollmentReply,
             options_.timings.request_timeout);
    if (decided.ok() && decided->enrollment_reply().ok()) {
      enroll_accepted_ = true;
      result_.enrollment["accepted_after_s"] =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - enroll_started_).count();
    }
    return;
  }
}

void LabRun::MaybeStall() {
  if (options_.stall_unit < 0 || stall_state_ == StallState::kResumed) return;
  const auto now = std::chrono::steady_clock::now();
  const bool stopped = stall_state_ == StallState::kStopped;
  const bool holding = hold_started_ != std::chrono::steady_clock::time_point{};
  if (options_.stall_after_calibration && !holding) return;
  const auto from = options_.stall_after_calibration ? hold_started_ : calibration_started_;
  if (!stopped && now - from < std::chrono::duration<double>(options_.stall_at_s)) return;
  if (stopped && now - stalled_at_ < std::chrono::duration<double>(options_.stall_for_s)) return;
  Stall(!stopped);
}

void LabRun::Stall(bool stop) {
  const NodeId unit = static_cast<NodeId>(options_.stall_unit);
  const std::string name = "node-" + std::to_string(unit);
  if (options_.stall_by == "link") {
    if (Status cut = hosts_->SetLink(name, !stop); !cut.ok()) {
      ST_LOG(kWarning) << "lab: --stall-by link: " << cut.ToString();
    }
  } else {
    for (const auto& child : supervisor_.children()) {
      if (child->name() == name) child->Signal(stop ? SIGSTOP : SIGCONT);
    }
  }
  const char* how = options_.stall_by == "link" ? "cut node-" : "stopped node-";
  const auto now = std::chrono::steady_clock::now();
  const auto from = options_.stall_after_calibration ? hold_started_ : calibration_started_;
  const double at_s = std::chrono::duration<double>(now - from).count();
  if (stop) {
    stall_state_ = StallState::kStopped;
    stalled_at_ = now;
    result_.stall = {{"unit", unit},
                     {"stopped_at_s", at_s},
                     {"during_calibration", !lines_.calibrated.count(unit)}};
    ST_LOG(kWarning) << "lab: " << how << unit << " (--stall-unit)";
  } else {
    stall_state_ = StallState::kResumed;
    result_.stall["resumed_at_s"] = at_s;
    ST_LOG(kWarning) << "lab: resumed node-" << unit << " (--stall-unit, by " << options_.stall_by
                     << ")";
  }
}

void LabRun::RecordKill() {
  if (!killed_) return;
  const NodeId unit = static_cast<NodeId>(options_.kill_unit);
  std::vector<NodeId> recalibrated;
  for (const auto& [id, line] : calibrated_at_kill_) {
    if (id == unit) continue;
    if (lines_.calibrated.at(id).round != line.round) recalibrated.push_back(id);
  }
  std::vector<NodeId> finished;
  for (const auto& [id, line] : lines_.calibrated) {
    if (id != unit) finished.push_back(id);
  }
  // Re-blend: each neighbour's first mask shown without the killed unit, from the kill.
  json reblend = json::object();
  double reblend_max_ms = 0.0;
  for (const report::BlendShown& line : lines_.reblends) {
    if (line.peer != unit) continue;
    const std::string id = std::to_string(line.id);
    if (reblend.contains(id)) continue;
    const double shown_ms = (line.shown_ns - kill_ns_) * 1e-6;
    const double detected_ms = (line.detected_ns - kill_ns_) * 1e-6;
    reblend[id] = {{"detected_ms", detected_ms},
                   {"noticed_by", line.noticed_by},
                   {"shown_ms", shown_ms},
                   {"compose_ms", line.compose_ms},
                   {"frame", report::ToJson(line.frame)}};
    reblend_max_ms = std::max(reblend_max_ms, shown_ms);
  }
  if (!reblend.empty()) {
    result_.live["reblend_ms_max"] = reblend_max_ms;
    result_.live["node_huge_pages"] = options_.node_huge_pages == "on";
    result_.live["reblend"] = reblend;
    result_.live["recalibrated_after_the_kill"] = recalibrated.size();
  }
  result_.kill = {{"unit", unit},
                  {"at_s", kill_at_s_},
                  {"counted_from", options_.kill_after_calibration ? "hold" : "calibration"},
                  {"during_calibration", killed_while_calibrating_},
                  {"others_calibrated", finished},
                  {"others_recalibrated_after_the_kill", recalibrated}};
}

void LabRun::MaybeKillCoordinator() {
  if (options_.kill_coordinator_at_s < 0 || coordinator_killed_) return;
  const auto now = std::chrono::steady_clock::now();
  if (now - hold_started_ < std::chrono::duration<double>(options_.kill_coordinator_at_s)) return;
  coordinator_killed_ = true;
  for (const auto& child : supervisor_.children()) {
    if (child->spec().role != "coordinator" || child->exited()) continue;
    supervisor_.ExpectExit(child.get());
    intended_kills_.insert(child->name());
    child->Signal(SIGKILL);
    child->WaitFor(options_.timings.reap_after_kill);
  }
  coordinator_kill_ms_ = SystemMs();
  ST_LOG(kWarning) << "lab: killed the coordinator (--kill-coordinator-at-s); restarting it";
  const std::string requests = lines_.coordinator_requests, events = lines_.coordinator_events;
  lines_.coordinator_events.clear();
  ChildProcess* restarted =
      StartChild("coordinator-2", "coordinator", CoordinatorArgs(requests, events));
  if (!restarted) return;
  const WaitOutcome ready =
      supervisor_.WaitUntil([&] { return !lines_.coordinator_events.empty(); },
                            ToMs(options_.start_timeout_s), stop_, Handler());
  coordinator_restart_ms_ = ready == WaitOutcome::kDone ? SystemMs() - coordinator_kill_ms_ : -1;
  if (lines_.coordinator_events.empty()) lines_.coordinator_events = events;
}

int LabRun::FramesLost(int64_t from_ms, int64_t window_ms, const std::set<NodeId>& skip) {
  if (options_.render == "off") return -1;
  if (frame_times_.empty()) {
    Expected<std::string> log = ReadInputFile(FrameLogPath(), size_t{256} << 20, "256 MiB");
    if (!log.ok()) return -1;
    std::istringstream lines(*log);
    std::string line;
    while (std::getline(lines, line)) {
      const json j = json::parse(line, nullptr, false);
      if (!j.is_object() || !j.contains("projector") || !j.contains("time_ms")) continue;
      frame_times_[j["projector"].get<NodeId>()].push_back(j["time_ms"].get<int64_t>());
    }
  }
  int worst = 0;
  for (const auto& [id, times] : frame_times_) {
    if (skip.count(id)) continue;
    int before = 0, after = 0;
    for (const int64_t t : times) {
      if (t >= from_ms - window_ms && t < from_ms) ++before;
      if (t >= from_ms && t < from_ms + window_ms) ++after;
    }
    worst = std::max(worst, before - after);
  }
  return worst;
}

void LabRun::RecordChaos() {
  const bool any = Chaos() || options_.fault_unit >= 0 || options_.cap_unit >= 0 ||
                   options_.link_latency_ms > 0 || options_.link_loss > 0 ||
                   (options_.kill_unit >= 0 && options_.kill_after_calibration) ||
                   options_.stall_unit >= 0;
  if (!any) return;
  json chaos = {{"faults", json::array()}};
  constexpr int64_t kWindowMs = 3000;
  const double hold_ms = static_cast<double>(hold_started_ms_);
  if (killed_ && options_.kill_after_calibration) {
    const NodeId unit = static_cast<NodeId>(options_.kill_unit);
    json f = {{"fault", "SIGKILL node-" + std::to_string(unit)}, {"at_s", kill_at_s_}};
    double detected = -1;
    const json reblends = result_.live.value("reblend", json::object());
    for (const auto& [id, r] : reblends.items()) {
      const double d = r.value("detected_ms", -1.0);
      if (d >= 0 && (detected < 0 || d < detected)) detected = d;
    }
    if (detected >= 0) f["detected_ms"] = detected;
    if (result_.live.contains("reblend_ms_max")) {
      f["recovered_ms"] = result_.live["reblend_ms_max"];
      f["note"] = "recovered: the last neighbour's first re-blended frame";
    }
    const int64_t kill_ms = static_cast<int64_t>(hold_ms + kill_at_s_ * 1e3);
    if (int lost = FramesLost(kill_ms, kWindowMs, {unit}); lost >= 0) f["frames_lost_max"] = lost;
    chaos["faults"].push_back(f);
  }
  if (!result_.stall.is_null()) {
    const NodeId unit = static_cast<NodeId>(options_.stall_unit);
    const std::string what =
        options_.stall_by == "link" ? "link down, host of node-" : "SIGSTOP node-";
    json f = {{"fault",
               what + std::to_string(unit) + " for " + FixedDigits(options_.stall_for_s, 1) + " s"},
              {"at_s", result_.stall.value("stopped_at_s", 0.0)},
              {"note", options_.stall_after_calibration
                           ? "stopped while the site showed"
                           : "at: counted from the calibration phase's start"}};
    if (options_.stall_after_calibration) {
      const int64_t at_ms =
          hold_started_ms_ + static_cast<int64_t>(result_.stall.value("stopped_at_s", 0.0) * 1e3);
      if (int lost = FramesLost(at_ms, kWindowMs, {unit}); lost >= 0) f["frames_lost_max"] = lost;
    }
    chaos["faults"].push_back(f);
  }
  if (coordinator_killed_) {
    json f = {{"fault", "SIGKILL coordinator, restart on the same database"},
              {"at_s", (coordinator_kill_ms_ - hold_started_ms_) * 1e-3}};
    if (coordinator_restart_ms_ >= 0) f["detected_ms"] = coordinator_restart_ms_;
    std::string note = "detected: the new coordinator ready";
    if (painter_) {
      // The painter's clock starts with the hold (within a millisecond).
      const double kill_s = (coordinator_kill_ms_ - hold_started_ms_) * 1e-3;
      const double back_s = painter_->FirstAckAfter(kill_s);
      if (back_s >= 0) {
        f["recovered_ms"] = (back_s - kill_s) * 1e3;
        note += "; recovered: the first annotation acknowledged after it";
      }
    }
    f["note"] = note;
    if (int lost = FramesLost(coordinator_kill_ms_, kWindowMs, {}); lost >= 0) {
      f["frames_lost_max"] = lost;
    }
    chaos["faults"].push_back(f);
  }
  if (options_.cap_unit >= 0) {
    chaos["faults"].push_back(
        {{"fault", "what reaches node-" + std::to_string(options_.cap_unit) + "'s host capped at " +
                       std::to_string(options_.cap_kbit) + " kbit/s (tc tbf, whole run)"},
         {"at_s", 0.0}});
  }
  if (options_.link_latency_ms > 0 || options_.link_loss > 0) {
    chaos["faults"].push_back(
        {{"fault", "every node's links: " + FixedDigits(options_.link_latency_ms, 1) + " +- " +
                       FixedDigits(options_.link_jitter_ms, 1) + " ms latency, " +
                       FixedDigits(options_.link_loss * 100, 1) + " % lost (whole run)"},
         {"at_s", 0.0},
         {"note", "counts: chaos.links"}});
  }
  if (options_.fault_unit >= 0) {
    chaos["faults"].push_back(
        {{"fault", "node-" + std::to_string(options_.fault_unit) + " drops " +
                       FixedDigits(options_.fault_drop_share * 100, 1) + " % and corrupts " +
                       FixedDigits(options_.fault_corrupt_share * 100, 1) +
                       " % of what it sends (whole run)"},
         {"at_s", 0.0},
         {"note", "counts: chaos.links"}});
  }
  if (painter_) {
    LabPainterResult painted = painter_->Verify(options_.timings.request_timeout);
    chaos["annotations"] = painted.ToJson();
  }
  result_.chaos = chaos;
}

void LabRun::FinishChaos(const std::vector<std::string>& killed_at_teardown) {
  if (result_.chaos.is_null()) return;
  json links = json::object();
  for (const auto& child : supervisor_.children()) {
    if (child->spec().role != "node") continue;
    const fs::path log = fs::path(options_.out_dir) / "logs" / (child->name() + ".log");
    Expected<std::string> text = ReadInputFile(log.string(), size_t{64} << 20, "64 MiB");
    if (!text.ok()) continue;
    std::istringstream lines(*text);
    std::string line;
    while (std::getline(lines, line)) {
      // The node's exit line (report::Messages) among its log's lines.
      if (line.empty() || line[0] != '{') continue;
      Expected<report::ReportLine> parsed = report::ParseReportLineText(line);
      if (parsed.ok() && std::holds_alternative<report::Messages>(*parsed)) {
        links[child->name()] = report::ToJson(*parsed);
      }
    }
  }
  result_.chaos["links"] = links;
  int crashed = 0;
  json crashes = json::array();
  for (const auto& child : supervisor_.children()) {
    if (intended_kills_.count(child->name())) continue;
    const std::string exit = child->DescribeExit();
    const bool hung = std::find(killed_at_teardown.begin(), killed_at_teardown.end(),
                                child->name()) != killed_at_teardown.end();
    if (exit != "exit status 0" || hung) {
      ++crashed;
      crashes.push_back({{"name", child->name()}, {"exit", exit}, {"hung", hung}});
    }
  }
  result_.chaos["processes_crashed"] = crashed;
  result_.chaos["crashes"] = crashes;
}

bool LabRun::Hold() {
  if (options_.hold_s <= 0) return true;
  Phase("hold", 0);
  hold_started_ = std::chrono::steady_clock::now();
  hold_started_ms_ = SystemMs();
  if (options_.annotate) {
    LabPainterOptions painter;
    painter.requests_endpoint = lines_.coordinator_requests;
    painter.site_keys = site_keys_;
    if (Status checked = painter.Check(); !checked.ok()) {
      return FailedWith("hold", checked.ToString());
    }
    painter_ = std::make_unique<LabPainter>(painter);
    painter_->Start();
  }
  const WaitOutcome outcome = supervisor_.WaitUntil(
      [&] {
        MaybeKill();
        MaybeStall();
        MaybeKillCoordinator();
        return false;
      },
      ToMs(options_.hold_s), stop_, Handler());
  if (painter_) painter_->Stop();
  if (outcome == WaitOutcome::kDeadline) {
    progress_.End();
    return true;
  }
  return Failed("hold", outcome, "", nullptr);
}

}  // namespace sandtable::sim::lab_internal
