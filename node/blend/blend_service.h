// BlendService: the node's blend (docs/blend.md), computed with its overlapping neighbours.
//
// Once the unit holds a calibration (SetCalibration), a worker casts its projector into the
// model as placed (node/blend/blend_field.h): its surface, its distance field, its level bound.
// The field goes to the neighbours (the units whose footprints overlap, from the calibration
// round; every linked peer when the round did not say) as a BlendShare; their fields come back
// the same way. Each field received is looked up at this projector's pixels (a worker), and the
// mask (alpha x intensity correction at the site's common level) goes to the render loop
// between frames. The common level is the minimum of every projector's bound: each share
// carries the lowest bound its sender knows, and a node that learns a lower one tells its
// neighbours (a level-only share), so it spreads neighbour to neighbour. A face that the
// projectors lighting it cannot bring to that level everywhere (a wall met at 60-85 degrees)
// shows one lower level: each node sends its neighbours the level each such face reaches at its
// pixels (Blender::FaceLevelBounds), and shows each face at the lowest it holds; the neighbours'
// lists are not passed on (a face lit by two projectors that do not overlap, with a third
// between, may show two levels).
//
// A neighbour that leaves (its connection drops: a process that dies closes its socket at once;
// its heartbeats stop for `peer_silence`; or the member list drops it) is forgotten: the mask is
// recomposed from what the node holds (no cast, no recalibration) and shown at once. If it is heard
// again (a connection that came back), its field is asked for anew. A newcomer's share asks for an
// answer; the node sends its own field back. An overlapping unit whose field has not come is
// asked again (options.ask_again, doubling). Bad shares (a field that does not fit its grid, a
// model that does not check) are logged, counted and dropped.
//
// JSON lines (cluster/report_lines.h), for the lab:
//   {"blend":ID,"blended":true,"cause":..,"neighbours":[..],"waiting_for":[..],"level_per_m2":..,
//    "faces_below_level":..,"face_level_min_per_m2":..,"cast_ms":..,"compose_ms":..,
//    "shown_ns":..,"bytes_sent":..,"bytes_received":..}
//                                   each time a new mask is shown (waiting_for: overlapping
//                                   units whose field it does not hold yet)
//   {"blend":ID,"mpcdi":PATH,"alpha_from":K}   the runner, each time it rewrote the MPCDI export
//   {"blend":ID,"reblend":"left","peer":K,"noticed_by":"connection"|"silence"|"member list",
//    "detected_ns":..,"shown_ns":..,"compose_ms":..}
// Threading: network thread, except the casts and lookups, which run on the node's workers
// under the service's own lock.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "cluster/report_lines.h"
#include "common/io/mpcdi.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/scene.h"
#include "node/blend/blend_field.h"
#include "node/net/node_service.h"
#include "node/render/render_loop.h"
#include "proto/envelope.pb.h"

namespace sandtable::node {

struct BlendServiceOptions {
  BlendOptions blend;
  // A neighbour silent this long (no heartbeat) has left. A killed process is noticed sooner,
  // when its socket closes; this catches a stalled one. 10 heartbeats: 8 nodes on 2 loaded
  // cores miss 300 ms now and then.
  std::chrono::milliseconds peer_silence{1000};
  // A neighbour whose field has not come this long after it was asked for is asked again (a
  // share lost while a link was down: the coordinator dropped one of the two for a moment, or on
  // a lossy link), then after twice as long, up to ask_again_max. A field received again is not
  // looked up again (SameField). Short, because a newcomer's share lost on its lossy link holds
  // its neighbour's re-blend with it until the ask comes again.
  std::chrono::milliseconds ask_again{500};
  std::chrono::milliseconds ask_again_max{16000};
  std::string export_dir;  // blend-<id>.png (the alpha mask) is written here (empty: not)
  // The mask goes to the round's runner (the MPCDI export) once no new one was composed for this
  // long: a site settling sends one map per node, not one per share heard.
  std::chrono::milliseconds alpha_quiet{1000};
  // Black-level matching (docs/blend.md): raise the black where fewer projectors overlap to the
  // site's highest black light, by at most max_lift of the projector's range. Needs the black
  // level the unit's camera measured (calibration.projector_response).
  bool black_match = false;
  double max_lift = 0.05;
  Status Check() const;
};

// BlendShare <-> DistanceField (the field's grid checked against its projector).
wire::BlendShare ShareFromField(const DistanceField& field, uint64_t round);
Expected<DistanceField> FieldFromShare(const wire::BlendShare& share);
// A share's face levels (nullopt: it says nothing of faces); an error for a face id below 0, a
// level that is not finite and positive, a face listed twice, or more than kMaxFaceLevels.
inline constexpr int kMaxFaceLevels = 1 << 20;
Expected<std::optional<FaceLevels>> FaceLevelsFromShare(const wire::BlendShare& share);

class BlendService : public NodeService {
 public:
  using Print = std::function<void(const report::ReportLine&)>;
  // `loop` (not owned) shows the masks; `model` (may be null: the table plane) as the render
  // loop draws it.
  BlendService(std::shared_ptr<const Scene> model, RenderLoop* loop, BlendServiceOptions options,
               Print print);
  ~BlendService() override;

  const char* name() const override { return "blend"; }
  bool ServesPeer(wire::Envelope::BodyCase body) const override;
  void OnPeerMessage(net::Incoming request, NodeRuntime& node) override;
  Status OnStep(NodeRuntime& node) override;

  // The calibration the unit now holds (network thread). `neighbours`: the units whose
  // footprints overlap its own (nullopt: unknown, every linked peer).
  // `runner`: the node that ran the round (it writes the site's MPCDI export); the mask shown
  // goes to it as a BlendAlpha once none newer came for `alpha_quiet` (kInvalidNodeId: none).
  void SetCalibration(const UnitCalibration& calibration, uint64_t round,
                      std::optional<std::set<NodeId>> neighbours, NodeRuntime& node,
                      NodeId runner = kInvalidNodeId);
  // The runner only: the site's MPCDI export (its regions "unit-<id>"), rewritten at `path` with
  // each region's alpha map as the masks come in.
  void SetSiteMpcdi(std::shared_ptr<const MpcdiSite> site, std::string path);
  // While another writer has the site's MPCDI file in hand (the node's export of the round, on
  // a worker): alpha maps are kept and written once it is released.
  void HoldSiteMpcdiWrites();
  void ReleaseSiteMpcdiWrites(NodeRuntime& node);

  // Shares and alpha maps refused so far (malformed, or fitting nothing here).
  uint64_t bad_messages() const { return bad_shares_; }

 private:
  struct Core;  // what the workers touch, under its lock
  // `noticed_by` (a static string, or null): how a neighbour that left was noticed.
  void Compose(NodeRuntime& node, const std::string& cause, NodeId peer,
               std::chrono::steady_clock::time_point detected, const char* noticed_by = nullptr);
  struct ComposeJob;     // Compose's copy of what the worker needs
  struct ComposedBlend;  // what the worker composed and showed
  static ComposedBlend ComposeAndShow(const ComposeJob& job);
  void OnBlendShown(NodeRuntime& node, const std::string& cause, NodeId peer,
                    std::chrono::steady_clock::time_point detected, double level,
                    const char* noticed_by, ComposedBlend shown);
  void SendShare(NodeId to, bool with_field, bool answer, NodeRuntime& node);
  // Looks a neighbour's field up at this projector's pixels (a worker), then recomposes.
  void ApplyField(NodeId from, const DistanceField& field, NodeRuntime& node);
  void TellLevel(NodeRuntime& node);  // the lowest level and the highest black light heard
  void TakeAlpha(NodeId unit, int width_px, int height_px, std::string values, NodeRuntime& node);
  // The same from a PNG (BlendAlpha.png), decoded on a worker; a PNG whose header states
  // another size, or that does not decode to an 8-bit grey image of it, is dropped.
  void TakeAlphaPng(NodeId unit, int width_px, int height_px, std::string png, NodeRuntime& node);
  // On a worker; repeats while dirty; its line names mpcdi_latest_.
  void WriteSiteMpcdi(NodeRuntime& node);
  void SendAlpha(NodeRuntime& node);  // the pending mask to the runner

  RenderLoop* loop_;
  BlendServiceOptions options_;
  Print print_;
  std::shared_ptr<const Scene> model_;
  std::shared_ptr<Core> core_;

  NodeId id_ = kInvalidNodeId;
  uint64_t round_ = 0;
  uint64_t generation_ = 0;  // bumped by each calibration
  bool ready_ = false;       // the own field is cast
  std::optional<std::set<NodeId>> neighbours_;
  std::set<NodeId> sent_to_;  // own field sent to, this calibration
  // The own field as sent (built by the cast's worker): sending never waits for the workers'
  // lock, which a neighbour's lookup holds for up to seconds on a loaded machine.
  std::shared_ptr<const wire::BlendShare> own_share_;
  struct Asked {
    std::chrono::steady_clock::time_point at;
    std::chrono::milliseconds interval{0};
  };
  std::map<NodeId, Asked> asked_;    // neighbours asked for their field, this calibration
  std::map<NodeId, double> bounds_;  // level bounds heard (and own)
  // Face levels (Blender::FaceLevelBounds): the own, as last sent (nullopt: not composed yet),
  // and each neighbour's latest. A face shows the lowest of them (and the site's level).
  std::optional<FaceLevels> own_faces_;
  std::map<NodeId, FaceLevels> neighbour_faces_;
  double level_told_ = 0.0;                 // the lowest level told to the neighbours
  double own_black_ = -1.0;                 // this projector's black level (< 0: unknown)
  std::map<NodeId, double> blacks_;         // the neighbours' black levels
  std::map<NodeId, double> black_peaks_;    // highest black light heard (and own), 1 / m^2
  double black_told_ = 0.0;                 // the highest black light told to the neighbours
  std::set<NodeId> holding_;                // neighbours whose field the blend holds
  std::map<NodeId, DistanceField> fields_;  // received, by sender (kept across calibrations)
  std::map<NodeId, std::chrono::steady_clock::time_point> dropped_;  // left, and when
  double cast_ms_ = 0.0;                                             // the last calibration's cast
  NodeId runner_ = kInvalidNodeId;
  std::shared_ptr<MpcdiSite> site_mpcdi_;  // the runner's export, with the alphas received
  std::string site_mpcdi_path_;
  bool mpcdi_writing_ = false, mpcdi_dirty_ = false;
  NodeId mpcdi_latest_ = kInvalidNodeId;  // the unit whose alpha map came in last
  int mpcdi_holds_ = 0;                   // HoldSiteMpcdiWrites() not yet released
  struct PendingAlpha {
    int width_px = 0, height_px = 0;
    std::string png;     // 8-bit grey PNG, for another node as runner
    std::string values;  // or the 8-bit values themselves, when this node is the runner
    std::chrono::steady_clock::time_point composed;
  };
  std::optional<PendingAlpha> pending_alpha_;  // the last mask, not yet sent to the runner
  uint64_t bytes_sent_ = 0, bytes_received_ = 0, bad_shares_ = 0;
};

}  // namespace sandtable::node
