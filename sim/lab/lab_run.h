// `sandtable-lab run`: one whole simulated site on localhost, measured against the truth.
//
// Phases (each shown on the terminal and timed in the report):
//   prepare         the site, scene, factory and true-pose files (lab_inputs.h)
//   start world     sandtable-world serve --site F --scene G --bind tcp://127.0.0.1:*
//                   -> {"ready":"sandtable-world","world":ENDPOINT}
//   start coordinator  sandtable-coordinator --requests tcp://127.0.0.1:* --events ...:*
//                   -> {"ready":"sandtable-coordinator","requests":..,"events":..}
//   (--curve: OUT/site.key is generated, mode 0600, and each of the three also gets
//    --curve-keys OUT/site.key, so every connection of the run is authenticated)
//   start nodes     per unit: sandtable-node --id N --coordinator REQ,EV --world W
//                   --factory F --true-pose T --export-dir DIR/calibration
//                   -> {"ready":"sandtable-node","id":N,...}            (k/N ready)
//   calibration     -> {"calibrated":N,"source":..,"json":..,"yaml":..} (k/N held)
//   show            the nodes' show: the table grid measured from above, the timeline played
//   blend           the nodes' blend: raw white and blended white measured on every surface
//   hold            optional: the site keeps running for hold_s (children watched)
//   metrics         the registration metric (registration_metric.h) on the exported files
//   report          report.json, report.md, pictures (lab_report.h, lab_images.h)
// Ports are chosen by the OS; readiness comes only from the JSON lines
// (cluster/report_lines.h). A child that dies early, a deadline that passes, or SIGINT /
// SIGTERM on the lab ends the run: every child is torn down (SIGTERM, SIGKILL after a grace
// period, always reaped), the report names the child, its exit status or signal and the last
// lines of its log, and the lab exits non-zero.
// The lab prints its own JSON lines on stdout for supervisors and tests:
//   {"lab":"phase","phase":"hold","hold_s":30}   when a phase starts
//   {"lab":"done","status":"ok","report":"DIR/report.json"}
// Exit codes: 0 ok; 1 a child, deadline or file failed; 2 usage; 3 the run completed and failed
// its verdict (registration over --max-rms-mm, model not found, a unit left out, a figure not
// measured: lab_verdict.h); 130 interrupted.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "sim/lab/lab_verdict.h"

namespace sandtable::sim {

// The exit code of a run that completed and failed its verdict (sweep and scale read its
// figures all the same).
inline constexpr int kLabExitVerdict = 3;

// The lab's fixed waits and timeouts, each named with its unit (the flags' timeouts are in
// LabRunOptions itself).
struct LabTimings {
  // A blend is settled when no node has shown a new mask for this long.
  std::chrono::milliseconds blend_settle{1500};
  // The longest wait for the blend to settle (after it: measured as it is, `unsettled`).
  std::chrono::milliseconds blend_wait{60000};
  // The longest wait for every node to show a test pattern.
  std::chrono::milliseconds pattern_wait{60000};
  // After a late unit's calibration: its neighbours' re-blend and recalibration may follow.
  std::chrono::milliseconds join_settle{2000};
  // A request to the coordinator (test pattern, timeline), and the painter's last acks.
  std::chrono::milliseconds request_timeout{10000};
  // A world request that renders (top views, the ground truth at many points).
  std::chrono::milliseconds world_render_timeout{300000};
  // The nodes flush their render logs once a second: the wait after the show for the last.
  std::chrono::milliseconds render_log_flush{1200};
  // The longest a piece of the lab's own work (a measure) may run while children are watched.
  std::chrono::milliseconds work_limit{3600000};
  // After SIGKILL, the longest wait for the child to be reaped.
  std::chrono::milliseconds reap_after_kill{5000};
  // How often a request's reply is looked for.
  std::chrono::milliseconds reply_poll{50};
  Status Check() const;
};

struct LabRunOptions {
  std::string site = "sandtable-3";
  std::string scene = "sandtable";
  std::string out_dir;
  uint64_t seed = 1;
  double hold_s = 0.0;
  std::string bin_dir;            // where sandtable-world/-coordinator/-node are ("" = find them)
  double start_timeout_s = 60.0;  // per readiness phase
  // Structured light on a grid site takes minutes of wall time: the world renders every
  // capture on one thread (grid-8: ~160 s, grid-16: ~190 s on a 2-core machine).
  double calibration_timeout_s = 900.0;
  double teardown_grace_s = 5.0;
  int metric_samples = 40000;
  int image_width_px = 640;
  // Every projector and camera of the site at this fraction of its resolution (scale runs of
  // many nodes on a small machine); 1 = as the site file or preset says.
  double resolution_scale = 1.0;
  // The units' device timing (sim/site/device_timing.h): "ideal", "real" (a 60 Hz projector
  // with two frames of lag, a 30 fps camera with a two-frame queue, repeated and lost frames),
  // or "" (as the site file says; presets are ideal).
  std::string device_timing;
  // The seed of the world's capture noise (sandtable-world serve --noise-seed): the same site
  // and seed with another noise shows how much a figure moves with the noise alone.
  uint64_t noise_seed = 1;
  // Membership heartbeat of the coordinator and the nodes, ms (a member is dead after 5 missed):
  // 0 = 100 ms up to 16 units, 100 ms x units / 16 beyond (64 processes on two cores: a
  // starved coordinator declared 56 of 64 nodes dead at once after a stall).
  int heartbeat_ms = 0;
  bool progress_tty = false;
  // The machine-readable phase lines on stdout ({"lab":"phase",...}); off when stdout is a
  // terminal, where they would land on the progress bar's line.
  bool phase_lines = true;
  bool curve = false;  // generate OUT/site.key (0600); world, coordinator, nodes require CURVE
  // Where the children run: "local" (this host's loopback) or "netns" (each on a host of its
  // own, a network namespace on a bridge, sim/lab/lab_hosts.h; the nodes find the coordinator
  // by its beacon, and CURVE is on as with --curve).
  std::string hosts = "local";
  // "structured-light" (the nodes calibrate themselves and find the model) or "true-pose"
  // (LAB TEST MODE: factory intrinsics + the true pose, the baseline).
  std::string calibration = "structured-light";
  // The model handed to the nodes: "" = the scene at a seeded unknown placement (up to 5 cm
  // and 10 degrees about z); a glTF FILE = exactly that file (true placement: as written).
  std::string model;
  // A directory holding the unit-<id>.json an earlier run exported (its DIR/calibration): each
  // node gets its file as --saved-calibration, checks it and skips the round when it holds.
  // Use the same --seed and --model as that run (the model's placement is part of it).
  std::string saved_calibration;
  // Self-calibration path of the nodes: "auto" (planar when every footprint is planar) or
  // "full" (docs/calibration.md, "Planar sites").
  std::string calibration_path = "auto";
  // The verdict on a completed run (sim/lab/lab_verdict.h): its registration bar
  // (--max-rms-mm, 0 = none) and the sample counts under which a figure is "not measured". A
  // run that fails it ends with status "failed", its reasons first in report.md, and exit
  // code 3.
  LabVerdictOptions verdict;
  // A unit started only once the others hold their calibration (a live join, docs/lab.md):
  // it is calibrated against them; the report says whether any of them was recalibrated.
  // -1: none.
  int join_late = -1;
  // --hosts netns: this unit starts with no site key (--enroll, docs/deploy.md "Accepting a new
  // unit"); the coordinator takes enrollment requests and the lab, as the operator, accepts the
  // unit once it asks. The report says how long it waited. -1: none.
  int enroll_unit = -1;
  // A unit the lab kills (SIGKILL) kill_at_s seconds after the calibration phase began: during
  // the round (a node lost mid-calibration) or, with a --hold-s past it, after (a node that
  // leaves). The run goes on; the report says what the others did. -1: none.
  int kill_unit = -1;
  double kill_at_s = 0.0;
  bool kill_after_calibration = false;  // kill_at_s counted from the hold phase's start
  // A unit the lab stalls (SIGSTOP, then SIGCONT stall_for_s later) stall_at_s seconds after
  // the calibration phase began: a node frozen by its machine's load; the coordinator drops
  // it and it registers again when it thaws. -1: none.
  // Extra arguments for every sandtable-node, verbatim (the sweep's knobs: --phase-steps 4 ..).
  std::vector<std::string> node_args;
  int stall_unit = -1;
  double stall_at_s = 0.0;
  double stall_for_s = 4.0;
  bool stall_after_calibration = false;  // stall_at_s counted from the hold's start
  // Chaos (docs/lab.md): `annotate` paints strokes through the coordinator's annotation
  // protocol during the hold (LabPainter; the coordinator keeps them in OUT/annotations.db) and
  // checks afterwards that every acknowledged point is there. kill_coordinator_at_s >= 0:
  // SIGKILL the coordinator that long into the hold and start it again on the same database and
  // endpoints. fault_unit >= 0: that node drops / corrupts those shares of what it sends.
  bool annotate = false;
  double kill_coordinator_at_s = -1.0;
  int fault_unit = -1;
  double fault_drop_share = 0.0;
  double fault_corrupt_share = 0.0;
  // Every node's links (what it sends to the coordinator and its peers): this latency, +- this
  // jitter (uniform, in order), and this share lost, seeded by --seed (the nodes' --fault-*
  // flags; there is no netem here, docs/lab.md). Not with fault_unit.
  double link_latency_ms = 0.0;
  double link_jitter_ms = 0.0;
  double link_loss = 0.0;
  // How --stall-unit stalls its unit: "signal" (SIGSTOP, SIGCONT) or "link" (--hosts netns:
  // its host's link down, then up: cut off from the site while it keeps running).
  std::string stall_by = "signal";
  // --hosts netns: what reaches this unit's host is capped at cap_kbit (tc tbf on its link), the
  // whole run. -1: none.
  int cap_unit = -1;
  int cap_kbit = 0;
  // LAB TEST: the nodes' clocks disagree as separate hosts' do: the units, in the site's order,
  // read +1, -1, +2, -2, ... times this many seconds off the machine's clock
  // (--test-clock-offset-s); the lab takes the offsets off again where it compares their times.
  double clock_offset_s = 0.0;
  // The show (docs/render.md): once calibrated, every node shows the table grid (the lab
  // measures how the projectors' lines coincide from above), then the show with the lab's
  // personnel tracks playing for show_s (frame times, timeline skew). render "off": none.
  std::string render = "on";
  double show_s = 4.0;
  double render_max_fps = 10.0;  // per node: the world takes every frame (~3 MB each)
  int grid_view_width_px = 1600;
  // The blend (docs/blend.md): once the show is measured, every node blends with its
  // overlapping neighbours; the lab measures the luminance from the world's truth, every node
  // showing raw white (before) and white through the full pipeline (after). "off": no blend.
  std::string blend = "on";
  // Black-level matching (docs/blend.md): "on" passes --black-match on to the nodes.
  std::string black_match = "off";
  // "on": each node's heap on transparent huge pages (GLIBC_TUNABLES=glibc.malloc.hugetlb=1:
  // glibc.malloc.arena_max=1 in its environment: every thread's allocations in the main heap,
  // on huge pages). A killed node's sockets close once its memory is unmapped; with huge pages
  // that is 30-50 ms sooner on this machine, and its neighbours notice the death sooner
  // (docs/blend.md, "A neighbour leaves").
  std::string node_huge_pages = "on";
  std::string command_line;  // for the report
  LabTimings timings;
  Status Check() const;
};

// Exit codes: 0 ok, 1 failed (a child died, a deadline passed, a file could not be written),
// 2 usage (bad site/scene), 130 interrupted.
int RunLab(const LabRunOptions& options, const std::atomic<bool>& stop, std::ostream& out,
           std::ostream& err);

}  // namespace sandtable::sim
