// The runner's side of the self-calibration (calibration_runner.h): the round's start and stages.
#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "common/base/log.h"
#include "common/base/thread_cpu_time.h"
#include "common/io/json_codec.h"
#include "common/io/mpcdi_builder.h"
#include "common/scene/procedural_scene.h"
#include "node/app/calibration_runner.h"
#include "node/calibration/join_solver.h"
#include "node/calibration/schedule.h"
#include "proto/convert.h"
#include "proto/envelope_stamper.h"

namespace sandtable::node {
namespace {

constexpr uint32_t kBlackSlot = 1;
constexpr uint32_t kWhiteSlot = 2;
constexpr uint32_t kMutedSlot = 3;
constexpr uint32_t kGreySlot = 10;  // kGreySlot + i: response level i

wire::CalibrationStep MakeStep(uint64_t round, wire::CalibrationAction action) {
  wire::CalibrationStep s;
  s.set_round(round);
  s.set_action(action);
  return s;
}

}  // namespace

CalibrationRunner::CalibrationRunner(const SelfCalibrationOptions& options,
                                     std::shared_ptr<const Scene> model,
                                     const CalibrationUnit& unit, CalibrationLink* link,
                                     CalibrationLedger* ledger)
    : options_(options), model_(std::move(model)), unit_(unit), link_(link), ledger_(ledger) {}

CalibrationRunner::~CalibrationRunner() = default;

void CalibrationRunner::OnAsk(const wire::RecalibrateAsk& ask) {
  // The first ask seen (and the first of a coordinator's new epoch) was made before this unit
  // joined, or before the coordinator restarted: already answered.
  if (!ask_epoch_ || *ask_epoch_ != ask.epoch()) {
    ask_epoch_ = ask.epoch();
    last_ask_id_ = ask.ask_id();
    return;
  }
  if (ask.ask_id() <= last_ask_id_) return;  // seen (the coordinator publishes it every second)
  last_ask_id_ = ask.ask_id();
  RecalibrationAsk a;
  a.id = ask.ask_id();
  a.all_units = ask.all_units();
  a.unit = ask.all_units() ? kInvalidNodeId : ask.node_id();
  asked_ = a;
  ST_LOG(kInfo) << "self-calibration: the operator asked to recalibrate "
                << (a.all_units ? std::string("the site") : "unit " + std::to_string(a.unit))
                << " (ask " << a.id << ")";
}

void CalibrationRunner::OnStep(NodeRuntime& node) {
  MaybeStartRound(node);
  RunnerStep(node);
}

RoundView CalibrationRunner::RoundViewNow(NodeRuntime& node) const {
  RoundView v;
  v.self = node.id();
  v.has_camera = unit_.has_camera();
  v.registered = node.registered();
  v.now = std::chrono::steady_clock::now();
  v.started = created_;
  const std::optional<wire::MemberList>& list = node.member_list();
  v.has_member_list = list.has_value();
  if (list) {
    for (const wire::Member& m : list->members()) {
      const wire::Capabilities& c = m.capabilities();
      if (!c.has_projector() || !c.has_camera()) continue;
      RoundMember member;
      member.id = m.node_id();
      if (member.id == node.id()) {
        member.state = node.calibration_state();
        member.linked = true;
      } else if (auto peer = node.peers().find(member.id); peer != node.peers().end()) {
        member.state = peer->second.calibration_state;
        member.linked = peer->second.heartbeats_received > 0;
      }
      v.members.push_back(member);
    }
    std::sort(v.members.begin(), v.members.end(),
              [](const RoundMember& a, const RoundMember& b) { return a.id < b.id; });
    v.member_list_age = node.member_list_age();
  }
  v.round_running = round_ && !round_->finished;
  v.ran_round = round_ && round_->finished;
  v.holds_site_solution = v.ran_round && last_solution_ != nullptr;
  v.site_units = last_solution_ ? last_solution_->calibrations.size() : 0;
  if (last_solution_) {
    for (const auto& [id, c] : last_solution_->calibrations) v.site_unit_ids.push_back(id);
  }
  if (round_) {
    v.last_round_members = round_->members;
    v.departed = round_->departed;
  }
  v.failed_rounds = failed_rounds_;
  v.last_round_ended = last_round_ended_;
  v.calibrated = unit_.calibrated();
  v.calibrated_by = unit_.calibrated_by();
  v.first_seen_calibrated_peer = first_seen_calibrated_peer_;
  v.last_step_from_other = unit_.last_step_from_other();
  v.first_seen_uncalibrated_member = first_seen_uncalibrated_member_;
  v.asked = asked_;
  return v;
}

void CalibrationRunner::MaybeStartRound(NodeRuntime& node) {
  const RoundView view = RoundViewNow(node);
  const RoundDecision d = DecideRound(view, options_.RoundPolicy());
  if (d.saw_calibrated_peer && !first_seen_calibrated_peer_) first_seen_calibrated_peer_ = view.now;
  if (!d.saw_uncalibrated_member) {
    first_seen_uncalibrated_member_.reset();
  } else if (!first_seen_uncalibrated_member_) {
    first_seen_uncalibrated_member_ = view.now;
  }
  if (d.why != last_round_why_) {
    if (d.transient) {
      ST_LOG(kDebug) << "self-calibration: " << d.why;
    } else {
      ST_LOG(kInfo) << "self-calibration: " << d.why << " (" << RoundActionName(d.action) << ")";
    }
    last_round_why_ = d.why;
  }
  if (d.ask_done && asked_) {
    if (d.action == RoundAction::kNone) {
      ST_LOG(kInfo) << "self-calibration: recalibration ask " << asked_->id << " is not this "
                    << "unit's to carry out (" << d.why << ")";
    }
    asked_.reset();
  }
  if (d.action != RoundAction::kRound && d.action != RoundAction::kJoinRound) return;
  std::map<NodeId, std::pair<int, int>> sizes;
  for (const wire::Member& m : node.member_list()->members()) {
    const wire::Capabilities& c = m.capabilities();
    sizes[m.node_id()] = {static_cast<int>(c.projector_width_px()),
                          static_cast<int>(c.projector_height_px())};
  }
  round_ = std::make_unique<Round>();
  Round& r = *round_;
  r.round = static_cast<uint64_t>(proto::SteadyNowNs());
  r.self = node.id();
  r.members = d.members;
  r.join = d.action == RoundAction::kJoinRound;
  r.projecting = d.projecting;
  r.projector_size = sizes;
  r.round_started = std::chrono::steady_clock::now();
  ST_LOG(kInfo) << "self-calibration: running " << (r.join ? "join " : "") << "round " << r.round
                << " for " << r.projecting.size() << " of " << r.members.size() << " units";
  PlanPrepass(r);
  r.stages.back().after = [this](NodeRuntime&) { PlanSequences(); };
}

// Pre-pass: the projecting units black, a black reference on every camera, then each
// projecting unit white alone, and its response by its own camera.
void CalibrationRunner::PlanPrepass(Round& r) {
  // (In a join round the calibrated units go on showing what they show: the reference holds
  // it.)
  const std::vector<NodeId>& members = r.members;
  Round::Stage black, reference;
  black.label = "pre-pass black";
  reference.label = "pre-pass reference";
  for (NodeId m : r.projecting) {
    wire::CalibrationStep show = MakeStep(r.round, wire::CALIBRATION_ACTION_SHOW);
    show.set_show(wire::SHOW_WHAT_BLACK);
    black.commands.push_back({m, show});
  }
  for (NodeId m : members) {
    wire::CalibrationStep capture = MakeStep(r.round, wire::CALIBRATION_ACTION_CAPTURE);
    capture.set_slot(kBlackSlot);
    reference.commands.push_back({m, capture});
  }
  r.stages.push_back(black);
  r.stages.push_back(reference);
  r.prepass_frames = 1;
  for (NodeId p : r.projecting) {
    Round::Stage white, capture, off;
    white.label = "pre-pass white " + std::to_string(p);
    wire::CalibrationStep show = MakeStep(r.round, wire::CALIBRATION_ACTION_SHOW);
    show.set_show(wire::SHOW_WHAT_WHITE);
    white.commands.push_back({p, show});
    white.light_of = {p};
    capture.label = "pre-pass capture " + std::to_string(p);
    for (NodeId c : members) {
      wire::CalibrationStep s = MakeStep(r.round, wire::CALIBRATION_ACTION_CAPTURE);
      s.set_slot(kWhiteSlot);
      s.set_reference_slot(kBlackSlot);
      s.set_about_projector(p);
      s.set_has_about_projector(true);
      capture.commands.push_back({c, s, p});
    }
    capture.light_of = {p};
    r.stages.push_back(white);
    r.stages.push_back(capture);
    // The projector's response, by its own camera (projector_response.h).
    if (!options_.response_levels.empty()) {
      std::vector<std::pair<wire::CalibrationStep, uint32_t>> shows;  // (show, slot)
      for (size_t i = 0; i < options_.response_levels.size(); ++i) {
        wire::CalibrationStep grey = MakeStep(r.round, wire::CALIBRATION_ACTION_SHOW);
        grey.set_show(wire::SHOW_WHAT_GREY);
        grey.set_grey_level(static_cast<uint32_t>(options_.response_levels[i]));
        shows.emplace_back(grey, kGreySlot + static_cast<uint32_t>(i));
      }
      wire::CalibrationStep muted = MakeStep(r.round, wire::CALIBRATION_ACTION_SHOW);
      muted.set_show(wire::SHOW_WHAT_MUTED);
      shows.emplace_back(muted, kMutedSlot);
      for (const auto& [show_step, slot] : shows) {
        Round::Stage show_stage, capture_stage;
        show_stage.label = "pre-pass response " + std::to_string(p);
        show_stage.commands.push_back({p, show_step});
        capture_stage.label = show_stage.label + " capture";
        wire::CalibrationStep s = MakeStep(r.round, wire::CALIBRATION_ACTION_CAPTURE);
        s.set_slot(slot);
        capture_stage.commands.push_back({p, s});
        show_stage.light_of = capture_stage.light_of = {p};
        r.stages.push_back(show_stage);
        r.stages.push_back(capture_stage);
      }
      Round::Stage fit;
      fit.label = "pre-pass response fit " + std::to_string(p);
      wire::CalibrationStep f = MakeStep(r.round, wire::CALIBRATION_ACTION_RESPONSE);
      f.set_reference_slot(kBlackSlot);
      f.set_white_slot(kWhiteSlot);
      f.set_muted_slot(kMutedSlot);
      f.set_slot(kGreySlot);
      for (int level : options_.response_levels) f.add_grey_levels(static_cast<uint32_t>(level));
      fit.commands.push_back({p, f});
      r.stages.push_back(fit);
      r.response_frames = static_cast<int>(shows.size());
      r.prepass_frames += r.response_frames;
    }
    off.label = "pre-pass off " + std::to_string(p);
    wire::CalibrationStep dark = MakeStep(r.round, wire::CALIBRATION_ACTION_SHOW);
    dark.set_show(wire::SHOW_WHAT_BLACK);
    off.commands.push_back({p, dark});
    r.stages.push_back(off);
    ++r.prepass_frames;
  }
}

// After the pre-pass: who sees whom, the schedule, the plans, one sequence per colour class,
// the decodes and the local geometry; then the solve.
void CalibrationRunner::PlanSequences() {
  Round& rr = *round_;
  // Who sees whom, the schedule, the plans.
  for (NodeId p : rr.projecting) {
    if (!rr.Active(p)) continue;
    std::set<NodeId> seeing;
    for (const auto& [c, count] : rr.lit[p]) {
      if (rr.Active(c) && static_cast<int>(count) >= options_.min_lit_pixels) seeing.insert(c);
    }
    if (seeing.empty()) {
      rr.left_out[p] = "projector " + std::to_string(p) + ": no camera sees it";
      ST_LOG(kWarning) << "self-calibration: " << rr.left_out[p];
      continue;
    }
    if (!seeing.count(p)) {
      rr.left_out[p] = "unit " + std::to_string(p) + ": its camera does not see its projector";
      ST_LOG(kWarning) << "self-calibration: " << rr.left_out[p];
      continue;
    }
    rr.cameras_seeing[p] = seeing;
  }
  // Conflicts: projector pairs whose lit regions some camera cannot tell apart.
  std::set<NodeId> scheduled;
  for (const auto& [p, seeing] : rr.cameras_seeing) scheduled.insert(p);
  const std::map<NodeId, std::set<NodeId>> graph = ConflictGraphFromPairs(scheduled, rr.overlaps);
  rr.colours = ColourGraph(graph);
  const int colour_count = ColourCount(rr.colours);
  for (const auto& [p, seeing] : rr.cameras_seeing) {
    const auto [w, h] = rr.projector_size[p];
    const uint32_t own = rr.lit[p][p];
    const double ratio = own > 0 ? std::sqrt(static_cast<double>(w) * h / own) : 2.0;
    rr.resolution[p] = ratio;
    // The coarsest camera: the own one, or a neighbour at the stated factor.
    const double coarsest =
        seeing.size() > 1 ? ratio * options_.neighbour_resolution_factor : ratio;
    rr.plans[p] = PlanPatterns(w, h, coarsest, options_.plan);
  }
  ST_LOG(kInfo) << "self-calibration: " << rr.cameras_seeing.size() << " projectors in "
                << colour_count << " colours";
  // A join round: the calibrated neighbours whose cameras saw a joining projector's light
  // blank it in what they display while its sequence is captured (and only then).
  Round::Stage blank, restore;
  blank.label = "neighbours blank";
  restore.label = "neighbours restore";
  if (rr.join) {
    std::set<NodeId> neighbours;
    for (const auto& [p, seeing] : rr.cameras_seeing) {
      for (NodeId cam : seeing) {
        if (std::find(rr.projecting.begin(), rr.projecting.end(), cam) != rr.projecting.end())
          continue;
        wire::CalibrationStep b = MakeStep(rr.round, wire::CALIBRATION_ACTION_BLANK);
        b.set_about_projector(p);
        b.set_has_about_projector(true);
        b.set_blank_on(true);
        blank.commands.push_back({cam, b});
        neighbours.insert(cam);
      }
    }
    for (NodeId cam : neighbours) {
      wire::CalibrationStep b = MakeStep(rr.round, wire::CALIBRATION_ACTION_BLANK);
      b.set_blank_on(false);
      restore.commands.push_back({cam, b});
    }
    if (!blank.commands.empty()) rr.stages.push_back(blank);
  }
  // One sequence per colour class; the neighbours restore after the last.
  for (int colour = 0; colour < colour_count; ++colour) {
    PlanColour(colour, colour_count, [&] {
      if (!restore.commands.empty()) rr.stages.push_back(restore);
    });
  }
  Round::Stage local;
  local.label = "local geometry";
  for (const auto& [p, seeing] : rr.cameras_seeing) {
    wire::CalibrationStep s = MakeStep(rr.round, wire::CALIBRATION_ACTION_LOCAL);
    uint32_t expected = 0;
    for (NodeId cam : seeing) expected += rr.Active(cam) ? 1 : 0;
    s.set_frames(expected);
    local.commands.push_back({p, s});
  }
  local.after = [this](NodeRuntime& n2) {
    if (round_->join) {
      StartJoinSolve(n2);
    } else {
      StartSolve(n2);
    }
  };
  rr.stages.push_back(local);
}

// One colour class's sequence: its projectors show their frames together, every camera that
// sees one of them captures each; then the projectors go dark and the cameras decode.
void CalibrationRunner::PlanColour(int colour, int colour_count,
                                   const std::function<void()>& restore) {
  Round& rr = *round_;
  std::vector<NodeId> projectors;
  std::set<NodeId> cameras;
  int frames = 0;
  for (const auto& [p, c] : rr.colours) {
    if (c != colour) continue;
    projectors.push_back(p);
    for (NodeId cam : rr.cameras_seeing[p]) cameras.insert(cam);
    const int f = MakePatternLayout(rr.plans[p]).frame_count;
    rr.frames_per_projector[p] = f;
    frames = std::max(frames, f);
  }
  const uint32_t base = 1000u * static_cast<uint32_t>(colour + 1);
  for (int f = 0; f < frames; ++f) {
    Round::Stage show, capture;
    show.label = "colour " + std::to_string(colour) + " frame " + std::to_string(f);
    capture.label = show.label + " capture";
    for (NodeId p : projectors) {
      wire::CalibrationStep s = MakeStep(rr.round, wire::CALIBRATION_ACTION_SHOW);
      if (f < rr.frames_per_projector[p]) {
        s.set_show(wire::SHOW_WHAT_PATTERN);
        s.set_frame(static_cast<uint32_t>(f));
        *s.mutable_plan() = PatternPlanToWire(rr.plans[p]);
      } else {
        s.set_show(wire::SHOW_WHAT_BLACK);
      }
      show.commands.push_back({p, s});
    }
    for (NodeId cam : cameras) {
      wire::CalibrationStep s = MakeStep(rr.round, wire::CALIBRATION_ACTION_CAPTURE);
      s.set_slot(base + static_cast<uint32_t>(f));
      capture.commands.push_back({cam, s});
    }
    show.light_of = capture.light_of = projectors;
    rr.stages.push_back(show);
    rr.stages.push_back(capture);
  }
  rr.site_frames += frames;
  if (colour == colour_count - 1) restore();
  Round::Stage off, decode;
  off.label = "colour " + std::to_string(colour) + " off";
  decode.label = "colour " + std::to_string(colour) + " decode";
  for (NodeId p : projectors) {
    wire::CalibrationStep s = MakeStep(rr.round, wire::CALIBRATION_ACTION_SHOW);
    s.set_show(wire::SHOW_WHAT_BLACK);
    off.commands.push_back({p, s});
    for (NodeId cam : rr.cameras_seeing[p]) {
      wire::CalibrationStep d = MakeStep(rr.round, wire::CALIBRATION_ACTION_DECODE);
      d.set_slot(base);
      d.set_frames(static_cast<uint32_t>(rr.frames_per_projector[p]));
      *d.mutable_plan() = PatternPlanToWire(rr.plans[p]);
      d.set_projector_id(p);
      d.set_grid_step_px(static_cast<uint32_t>(options_.grid_step_px));
      decode.commands.push_back({cam, d});
    }
  }
  // The last decode of each camera in this colour frees its captures.
  std::set<NodeId> released;
  for (auto it = decode.commands.rbegin(); it != decode.commands.rend(); ++it) {
    if (released.insert(it->to).second) it->step.set_release_slots(true);
  }
  rr.stages.push_back(off);
  rr.stages.push_back(decode);
}

bool CalibrationRunner::EndStage(NodeRuntime& node) {
  Round& r = *round_;
  r.stage_active = false;
  if (!r.current_light_of.empty()) {
    const double s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - r.stage_started).count();
    for (NodeId p : r.current_light_of) r.measured_device_s[p] += s;
    r.measured_site_device_s += s;
    r.current_light_of.clear();
  }
  if (r.current_after) {
    auto after = std::move(r.current_after);
    r.current_after = nullptr;
    after(node);
  }
  return !r.solving && !r.finished;
}

void CalibrationRunner::RunnerStep(NodeRuntime& node) {
  if (!round_ || round_->finished || round_->solving) return;
  Round& r = *round_;
  const auto now = std::chrono::steady_clock::now();
  if (r.stage_active) {
    // Members that left, or did not answer in time, are left out of the rest of the round.
    for (auto it = r.awaiting.begin(); it != r.awaiting.end();) {
      const NodeId to = it->second.to;
      bool gone = false;
      if (to != r.self && !node.peers().count(to)) {
        auto since = r.missing_since.emplace(to, now).first;
        gone = now - since->second >= options_.member_grace;
        r.unsent.insert(it->first);
      } else {
        r.missing_since.erase(to);
        // Unanswered: sent again after step_retry, then 2x, 4x, 8x that (a loaded site's slow
        // steps are not flooded with copies).
        if (to != r.self && now - it->second.sent_at >=
                                options_.step_retry * (1 << std::min(it->second.resends, 3))) {
          r.unsent.insert(it->first);  // unanswered for step_retry: its answer may be lost
        }
        if (r.unsent.count(it->first)) {  // linked again, or unanswered: the step goes again
          wire::Envelope e;
          *e.mutable_calibration_step() = it->second.step;
          it->second.sent_at = now;
          ++it->second.resends;
          if (link_->Send(to, std::move(e), node)) {
            r.unsent.erase(it->first);
            ST_LOG(kInfo) << "self-calibration: step " << it->first << " sent again to unit " << to;
          }
        }
      }
      const bool late = now - std::max(r.stage_started, r.stage_progress) > options_.step_timeout;
      if (gone || late) {
        const std::string why = "unit " + std::to_string(to) +
                                (gone ? ": left the site during calibration"
                                      : ": no answer to a calibration step in " +
                                            std::to_string(options_.step_timeout.count() / 1000) +
                                            " s (nor from any other unit)");
        if (!r.left_out.count(to)) {
          r.left_out[to] = why;
          if (gone) r.departed.insert(to);
          ST_LOG(kWarning) << "self-calibration: " << why;
        }
        r.unsent.erase(it->first);
        it = r.awaiting.erase(it);
      } else {
        ++it;
      }
    }
    if (!r.awaiting.empty()) return;
    if (!EndStage(node)) return;
  }
  while (!r.stage_active && !r.stages.empty()) {
    Round::Stage stage = std::move(r.stages.front());
    r.stages.pop_front();
    r.current_after = stage.after;
    r.current_light_of = stage.light_of;
    r.stage_active = true;
    r.stage_started = now;
    ++r.stages_started;
    ReportProgress(r, stage.label, stage.light_of);
    std::vector<Round::Command> to_send;
    for (Round::Command& c : stage.commands) {
      if (!r.Active(c.to)) continue;
      if (c.step.action() == wire::CALIBRATION_ACTION_LOCAL) {
        // The sets the projecting node waits for: from the cameras still in the round (one
        // left out since the plan sends none; waiting for it would cost kLocalWaitForSets).
        uint32_t expected = 0;
        for (NodeId cam : r.cameras_seeing[c.to]) expected += r.Active(cam) ? 1 : 0;
        c.step.set_frames(expected);
      }
      c.step.set_step(r.next_step++);
      c.sent_at = now;
      r.awaiting[c.step.step()] = c;
      to_send.push_back(c);
    }
    for (const Round::Command& c : to_send) {
      wire::Envelope e;
      *e.mutable_calibration_step() = c.step;
      if (!link_->Send(c.to, std::move(e), node)) r.unsent.insert(c.step.step());
    }
    if (r.awaiting.empty() && !EndStage(node)) return;  // nothing to wait for
  }
}

namespace {

// The part of the round a stage's label belongs to: "pre-pass", "structured light, colour N",
// else the label itself ("local geometry", "neighbours blank", "solve").
std::string StepOfLabel(const std::string& label) {
  if (label.rfind("pre-pass", 0) == 0) return "pre-pass";
  if (label.rfind("colour ", 0) == 0) {
    const size_t end = label.find(' ', 7);
    return "structured light, " + label.substr(0, end);
  }
  return label;
}

}  // namespace

void CalibrationRunner::ReportProgress(Round& r, const std::string& detail,
                                       const std::vector<NodeId>& units) {
  const auto now = std::chrono::steady_clock::now();
  const std::string step = StepOfLabel(detail);
  if (step == r.progress_step && now - r.progress_at < std::chrono::seconds(1)) return;
  r.progress_step = step;
  r.progress_at = now;
  report::RoundProgress line;
  line.id = r.self;
  line.round = r.round;
  line.stage = r.stages_started;
  line.step = step;
  line.detail = detail;
  line.units = units;
  line.elapsed_s = std::chrono::duration<double>(now - r.round_started).count();
  link_->Progress(line);
}

void CalibrationRunner::HandleDone(NodeId from, const wire::CalibrationStepDone& done,
                                   NodeRuntime& node) {
  (void)node;
  if (!round_ || done.round() != round_->round) return;
  Round& r = *round_;
  auto it = r.awaiting.find(done.step());
  if (it == r.awaiting.end() || it->second.to != from) return;
  const Round::Command command = it->second;
  if (done.ok() && command.step.action() == wire::CALIBRATION_ACTION_LOCAL &&
      !r.inputs.count(from) && !r.left_out.count(from)) {
    // A unit sends its CalibrationInput before the done, on the same connection: a done without
    // it means the input was lost on the way (a lossy link drops or corrupts it). The step stays
    // awaited and goes again at its retry; the unit answers a repeated step with the same input
    // and done. Taken as done, the round would go on without the unit ("sent no calibration
    // input").
    ST_LOG(kInfo) << "self-calibration: unit " << from << " finished step " << done.step()
                  << " but its calibration input did not come; asking again";
    r.unsent.insert(done.step());  // sent again at the runner's next turn, not after step_retry
    return;
  }
  r.awaiting.erase(it);
  r.stage_progress = std::chrono::steady_clock::now();
  r.compute_s[from] += done.compute_s();
  if (!done.ok()) {
    ST_LOG(kWarning) << "self-calibration: " << done.message();
    r.notes.push_back(done.message());
    if (command.step.action() == wire::CALIBRATION_ACTION_CAPTURE ||
        command.step.action() == wire::CALIBRATION_ACTION_SHOW) {
      if (!r.left_out.count(from)) r.left_out[from] = done.message();
    }
    return;
  }
  if (command.step.action() == wire::CALIBRATION_ACTION_CAPTURE &&
      command.about != kInvalidNodeId) {
    r.lit[command.about][from] = done.lit_pixels();
    for (uint32_t other : done.overlapping_projectors()) {
      r.overlaps.insert(
          {std::min<NodeId>(other, command.about), std::max<NodeId>(other, command.about)});
    }
  }
  if (command.step.action() == wire::CALIBRATION_ACTION_RESPONSE) {
    if (done.response_gamma() > 0) {
      r.response[from] = {{"gamma", done.response_gamma()},
                          {"black_level", done.response_black_level()},
                          {"camera_pixels", done.response_pixels()}};
    } else {
      r.response[from] = {{"error", done.message()}};
    }
  }
  if (command.step.action() == wire::CALIBRATION_ACTION_BLANK && command.step.blank_on()) {
    r.blanked_px[from] = std::max(r.blanked_px[from], done.blanked_pixels());
  }
  if (command.step.action() == wire::CALIBRATION_ACTION_DECODE && done.points() < 50) {
    ST_LOG(kWarning) << "self-calibration: camera " << from << " decoded " << done.points()
                     << " points of projector " << command.step.projector_id()
                     << " (too few to use)";
    r.notes.push_back("camera " + std::to_string(from) + " decoded " +
                      std::to_string(done.points()) + " points of projector " +
                      std::to_string(command.step.projector_id()) + " (too few to use)");
  }
}

void CalibrationRunner::HandleInput(NodeId from, const wire::CalibrationInput& input,
                                    NodeRuntime& node) {
  (void)node;
  if (!round_ || input.round() != round_->round || input.unit_id() != from) return;
  if (!input.ok()) {
    round_->left_out[from] = input.message();
    return;
  }
  if (!input.message().empty()) round_->notes.push_back(input.message());
  round_->inputs[from] = input;
}

}  // namespace sandtable::node
