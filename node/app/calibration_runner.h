// The runner's side of the cluster's self-calibration (self_calibration_service.h): it asks the
// round policy when to run a round, plans and sends the round's steps, collects the units'
// inputs, solves the site on a worker and sends each unit its result. Also the wire
// conversions of the pattern plan. Internal to node/app; the service owns it and routes its
// messages.
#pragma once

#include <chrono>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "common/structured_light/pattern_sequence.h"
#include "common/structured_light/projector_grid.h"
#include "node/app/calibration_link.h"
#include "node/app/calibration_unit.h"
#include "node/app/round_policy.h"
#include "node/app/self_calibration_service.h"
#include "proto/calibration.pb.h"

namespace sandtable::node {

PatternOptions PatternOptionsFromWire(const wire::PatternPlan& plan);
wire::PatternPlan PatternPlanToWire(const PatternOptions& patterns);
// The grid points of a correspondence set (none when the arrays differ in size; pairs with a
// non-finite coordinate are skipped), and the other way.
std::vector<ProjectorGridPoint> GridPointsFromWire(const wire::CorrespondenceSet& set);
void GridPointsToWire(const std::vector<ProjectorGridPoint>& points, wire::CorrespondenceSet* set);

class CalibrationRunner {
 public:
  // `unit` is this node's own side (what the round policy reads of it); `options`, `link` and
  // `ledger` are the service's.
  CalibrationRunner(const SelfCalibrationOptions& options, std::shared_ptr<const Scene> model,
                    const CalibrationUnit& unit, CalibrationLink* link, CalibrationLedger* ledger);
  ~CalibrationRunner();

  // The coordinator's recalibrate_ask (published every second): a new one is kept for the
  // round policy (RoundView::asked) until it is answered.
  void OnAsk(const wire::RecalibrateAsk& ask);
  // Every step of the node: a round started when the policy says so, the current one driven.
  void OnStep(NodeRuntime& node);
  // Messages for this side (the service routes them).
  void HandleDone(NodeId from, const wire::CalibrationStepDone& done, NodeRuntime& node);
  void HandleInput(NodeId from, const wire::CalibrationInput& input, NodeRuntime& node);

 private:
  // A round's state, from its start to its results.
  struct Round {
    struct Command {
      NodeId to = kInvalidNodeId;
      wire::CalibrationStep step;
      NodeId about = kInvalidNodeId;  // CAPTURE in the pre-pass: the projector that is white
      std::chrono::steady_clock::time_point sent_at{};  // last sent (step_retry)
      int resends = 0;                                  // the wait doubles with each
    };
    struct Stage {
      std::vector<Command> commands;
      std::function<void(NodeRuntime&)> after;  // runs when every command is answered
      std::string label;
      // The projectors whose light this stage shows or captures (its time is theirs on the
      // devices: measured_device_s).
      std::vector<NodeId> light_of;
    };

    uint64_t round = 0;
    NodeId self = kInvalidNodeId;
    std::vector<NodeId> members;
    // The units whose projectors are calibrated in this round: all members, or in a join round
    // (join) the units that joined a calibrated site (the others are held).
    std::vector<NodeId> projecting;
    bool join = false;
    std::map<NodeId, std::pair<int, int>> projector_size;  // from the Hello capabilities
    std::map<NodeId, std::string> left_out;                // unit -> why
    // Of those, the units left out because they left the site or stopped answering: when one
    // comes back it is calibrated again (docs/calibration.md, "A unit that comes back").
    std::set<NodeId> departed;
    // Units awaited that are not in the member list, since when (a loaded unit whose heartbeats
    // stalled is dropped by the coordinator and registers again at once: not gone yet).
    std::map<NodeId, std::chrono::steady_clock::time_point> missing_since;
    // Awaited steps that may not have reached their unit (the send failed, or the unit dropped
    // out of the member list while it was awaited, taking its link's queue with it): sent again
    // once the unit is linked again.
    std::set<uint32_t> unsent;
    std::deque<Stage> stages;
    std::map<uint32_t, Command> awaiting;  // by step number
    std::function<void(NodeRuntime&)> current_after;
    std::vector<NodeId> current_light_of;
    // Wall time of the stages that showed or captured each projector's light, and of all of
    // them (projectors of one colour share theirs).
    std::map<NodeId, double> measured_device_s;
    double measured_site_device_s = 0.0;
    std::chrono::steady_clock::time_point stage_started{};
    // The stage's last answer (or its start): units are late only when the whole stage has
    // made no progress for step_timeout (a 64-unit stage queues at one world; docs/lab.md).
    std::chrono::steady_clock::time_point stage_progress{};
    std::chrono::steady_clock::time_point round_started{};
    uint32_t next_step = 1;
    bool stage_active = false;
    // Progress lines (ReportProgress): stages started, the last line's step and time.
    int stages_started = 0;
    std::string progress_step;
    std::chrono::steady_clock::time_point progress_at{};

    // Pre-pass and plan.
    std::map<NodeId, std::map<NodeId, uint32_t>> lit;  // lit[projector][camera]
    std::map<NodeId, std::set<NodeId>> cameras_seeing;
    std::set<std::pair<NodeId, NodeId>> overlaps;  // projector pairs a camera cannot separate
    std::map<NodeId, int> colours;
    std::map<NodeId, PatternOptions> plans;
    std::map<NodeId, double> resolution;  // projector px per own-camera px
    int prepass_frames = 0;
    int site_frames = 0;
    std::map<NodeId, int> frames_per_projector;

    // Inputs and the solve.
    std::map<NodeId, wire::CalibrationInput> inputs;
    std::map<NodeId, double> compute_s;         // per node, from the step answers
    std::map<NodeId, uint32_t> blanked_px;      // join round: what each neighbour blanked
    std::map<NodeId, nlohmann::json> response;  // each projector's response as its camera fitted it
    int response_frames = 0;                    // pre-pass frames per projector for it
    std::string path;  // "planar" or "full" (docs/calibration.md, "Planar sites")
    std::string path_reason;
    bool solving = false;
    bool finished = false;
    std::vector<std::string> notes;

    bool Active(NodeId unit) const { return !left_out.count(unit); }
  };

  // What the round policy needs to know, now.
  RoundView RoundViewNow(NodeRuntime& node) const;
  void MaybeStartRound(NodeRuntime& node);
  // The round's stages: the pre-pass, then (once it is answered) the sequences.
  void PlanPrepass(Round& r);
  void PlanSequences();
  void PlanColour(int colour, int colour_count, const std::function<void()>& restore);
  void RunnerStep(NodeRuntime& node);
  // A progress line (report::RoundProgress) for a stage or the solve: when its step differs
  // from the last line's, else at most once a second.
  void ReportProgress(Round& r, const std::string& detail, const std::vector<NodeId>& units);
  // The current stage is answered: runs its `after`; false when the round moved on to the
  // solve (nothing more to send).
  bool EndStage(NodeRuntime& node);
  void StartSolve(NodeRuntime& node);
  void StartJoinSolve(NodeRuntime& node);
  // The round's inputs as the solvers take them (units that sent none are left out).
  void CollectInputs(ClusterObservations* observations, std::map<NodeId, LocalGeometry>* local);
  // True (the round dropped, a new one to start) when units left the round, are back, and
  // the round's solution (null: failed) has fewer than two units.
  bool RoundAgainForReturners(const ClusterSolution* solution, NodeRuntime& node);
  // `solution` is null when the solve failed with `status`.
  void FinishRound(const ClusterSolution* solution, const Status& status, double solve_cpu_s,
                   NodeRuntime& node);
  void SendResults(const ClusterSolution* solution, const Status& status,
                   const std::string& report_text, NodeRuntime& node);

  const SelfCalibrationOptions& options_;
  std::shared_ptr<const Scene> model_;
  const CalibrationUnit& unit_;
  CalibrationLink* link_;
  CalibrationLedger* ledger_;
  std::unique_ptr<Round> round_;  // the last round this unit ran (null: none yet)
  // The runner's last solved site (every unit it calibrated; joined units are added), which a
  // join round holds the joining units against.
  std::shared_ptr<ClusterSolution> last_solution_;
  const std::chrono::steady_clock::time_point created_ = std::chrono::steady_clock::now();
  // For the round policy: when a calibrated peer, and a member without a calibration (since
  // the last time there was none), were first seen; the last decision's words (logged when
  // they change).
  std::optional<std::chrono::steady_clock::time_point> first_seen_calibrated_peer_;
  std::optional<std::chrono::steady_clock::time_point> first_seen_uncalibrated_member_;
  std::string last_round_why_;
  // The operator's asks: the coordinator's epoch and the newest ask id seen, and the one not
  // answered yet.
  std::optional<uint64_t> ask_epoch_;
  uint64_t last_ask_id_ = 0;
  std::optional<RecalibrationAsk> asked_;
  // Rounds in a row that left a unit they were to calibrate without a calibration, and when
  // the last round ended (the round policy's retries).
  int failed_rounds_ = 0;
  std::optional<std::chrono::steady_clock::time_point> last_round_ended_;
};

}  // namespace sandtable::node
