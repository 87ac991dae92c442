// sandtable-lab: runs a whole simulated site on localhost (sandtable-world, sandtable-coordinator
// and one sandtable-node per unit) and measures it against the world's truth (docs/lab.md).
//
//   sandtable-lab run [--site PRESET|FILE] [--scene PRESET|FILE] --out DIR [--seed N]
//                     [--hold-s S] [--bin-dir DIR] [--samples N] [--start-timeout-s S]
//                     [--calibration-timeout-s S] [--image-width W] [--progress auto|bar|plain]
//                     [--calibration structured-light|true-pose] [--model FILE.gltf]
//                     [--saved-calibration DIR] [--calibration-path auto|full]
//                     [--join-late ID] [--kill-unit ID --kill-at-s S]
//                     [--stall-unit ID --stall-at-s S --stall-for-s D] [--node-arg=ARG ...]
//                     [--stall-after-calibration] [--annotate] [--kill-coordinator-at-s S]
//                     [--fault-unit ID --fault-drop-share P --fault-corrupt-share P]
//   sandtable-lab sweep [--site ..] [--scene ..] --out DIR [--seed N] [--only CONFIG ..]
//   sandtable-lab scale --nodes 2,4,8 [--scene city] --out DIR [--seed N] [--reblend]
//   sandtable-lab chaos [--site sandtable-3] [--scene ..] --out DIR [--seed N] [--runs 5]
//   sandtable-lab html REPORT.md [-o REPORT.html] [--title T]   (any report, pictures inlined)
//
// Exit codes: 0 ok, 1 the run failed (report written), 2 usage, 130 interrupted (SIGINT or
// SIGTERM: the site is torn down and the report says so).
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <filesystem>
#include <iostream>
#include <string>

#include "common/base/file_io.h"
#include "common/base/log.h"
#include "common/base/main_guard.h"
#include "common/cli/command_line.h"
#include "sim/lab/lab_chaos.h"
#include "sim/lab/lab_html.h"
#include "sim/lab/lab_run.h"
#include "sim/lab/lab_scale.h"
#include "sim/lab/lab_sweep.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

namespace cli = sandtable::cli;
namespace sim = sandtable::sim;

// The subcommands' flags, each into the options it fills (kept alive by Run).
void AddRunFlags(CLI::App* run, sim::LabRunOptions& options) {
  run->add_option("--site", options.site,
                  "Site: sandtable-3, grid-N (1..64), flat-4, random:SEED (a random sound site), "
                  "or a site file");
  run->add_option("--scene", options.scene,
                  "Scene: sandtable, city, flat, random:SEED (terrain and structures), or a "
                  "glTF file");
  run->add_option("--out", options.out_dir, "Output directory (report, logs, calibrations)")
      ->required();
  run->add_option("--seed", options.seed, "Seed of the scene preset, factory errors and metric")
      ->check(cli::Integer<uint64_t>(0, UINT64_MAX));
  run->add_option("--hold-s", options.hold_s,
                  "Keep the site running this long after calibration (children watched)")
      ->check(cli::Real(0.0, 86400.0));
  run->add_option("--bin-dir", options.bin_dir,
                  "Directory of sandtable-world/-coordinator/-node (default: beside this program, "
                  "then the build tree)");
  run->add_option("--max-rms-mm", options.verdict.max_rms_mm,
                  "the registration's bar: a completed run whose site rms is over it fails "
                  "(status failed, exit code 3); 0: no bar")
      ->check(cli::Real(0.0, 1e6));
  run->add_option("--samples", options.metric_samples,
                  "Surface points sampled by the registration metric")
      ->check(cli::Integer<int>(1, 10000000));
  run->add_option("--start-timeout-s", options.start_timeout_s,
                  "Deadline of each start phase (readiness lines)")
      ->check(cli::Real(0.1, 3600.0));
  run->add_option("--calibration-timeout-s", options.calibration_timeout_s,
                  "Deadline for every node to report its calibration")
      ->check(cli::Real(0.1, 36000.0));
  run->add_option("--calibration", options.calibration,
                  "structured-light (default: the nodes calibrate themselves and find the "
                  "model) or true-pose (test mode: factory intrinsics + the true pose, the "
                  "baseline)")
      ->check(CLI::IsMember({"structured-light", "true-pose"}));
  run->add_option("--model", options.model,
                  "the glTF model handed to the nodes as is (default: the scene at a seeded "
                  "unknown placement, up to 5 cm and 10 degrees about z)")
      ->check(CLI::ExistingFile);
  run->add_option("--saved-calibration", options.saved_calibration,
                  "DIR/calibration of an earlier run (same seed and model): the nodes check "
                  "their saved calibrations and skip the round when they hold")
      ->check(CLI::ExistingDirectory);
  run->add_option("--calibration-path", options.calibration_path,
                  "self-calibration: auto (the planar path when every footprint is planar) or "
                  "full (for comparison)")
      ->check(CLI::IsMember({"auto", "full"}));
}

// `run`'s faults: kills, stalls, the coordinator's restart, faulty links, a late join.
void AddRunFaultFlags(CLI::App* run, sim::LabRunOptions& options) {
  cli::NoDefaultShown(
      run->add_option("--kill-unit", options.kill_unit,
                      "SIGKILL this unit --kill-at-s seconds after calibration began (during the "
                      "round, or after it with a longer --hold-s); the run goes on")
          ->check(cli::Integer<int>(0, 1 << 20)));
  run->add_option("--kill-at-s", options.kill_at_s, "when --kill-unit strikes (s)")
      ->check(cli::Real(0.0, 3600.0));
  run->add_flag("--kill-after-calibration", options.kill_after_calibration,
                "count --kill-at-s from the hold phase (every unit calibrated): a node that "
                "leaves a calibrated site");
  run->add_option("--node-arg", options.node_args,
                  "an argument for every sandtable-node, verbatim, written with '=': "
                  "--node-arg=--phase-steps=4 (repeat it; the sweep's knobs, sandtable-node "
                  "--help)");
  cli::NoDefaultShown(
      run->add_option(
             "--stall-unit", options.stall_unit,
             "SIGSTOP this unit --stall-at-s seconds after calibration began and SIGCONT it "
             "--stall-for-s later: a node frozen by load (dropped, then back)")
          ->check(cli::Integer<int>(0, 1 << 20)));
  run->add_option("--stall-at-s", options.stall_at_s, "when --stall-unit stops (s)")
      ->check(cli::Real(0.0, 3600.0));
  run->add_option("--stall-for-s", options.stall_for_s, "how long --stall-unit stays stopped (s)")
      ->check(cli::Real(0.01, 3600.0));
  run->add_flag("--stall-after-calibration", options.stall_after_calibration,
                "count --stall-at-s from the hold's start (after calibration) instead");
  run->add_flag("--annotate", options.annotate,
                "paint strokes through the coordinator during the hold (its database in "
                "OUT/annotations.db) and check every acknowledged point afterwards");
  cli::NoDefaultShown(
      run->add_option("--kill-coordinator-at-s", options.kill_coordinator_at_s,
                      "SIGKILL the coordinator this long into the hold and restart it on the same "
                      "database and endpoints")
          ->check(cli::Real(0.0, 3600.0)));
  cli::NoDefaultShown(
      run->add_option("--fault-unit", options.fault_unit,
                      "this node drops / corrupts a share of the messages it sends (whole run)")
          ->check(cli::Integer<int>(0, 1 << 20)));
  run->add_option("--fault-drop-share", options.fault_drop_share,
                  "share of --fault-unit's messages dropped")
      ->check(cli::Real(0.0, 1.0));
  run->add_option("--fault-corrupt-share", options.fault_corrupt_share,
                  "share of --fault-unit's messages corrupted (bytes flipped)")
      ->check(cli::Real(0.0, 1.0));
  run->add_option("--link-latency-ms", options.link_latency_ms,
                  "every node's messages leave this much later (in order; the nodes' own fault "
                  "injection: no netem here)")
      ->check(cli::Real(0.0, 10000.0));
  run->add_option("--link-jitter-ms", options.link_jitter_ms,
                  "the latency varies by up to this much either way (uniform)")
      ->check(cli::Real(0.0, 10000.0));
  run->add_option("--link-loss", options.link_loss, "share of every node's messages lost")
      ->check(cli::Real(0.0, 0.99));
  run->add_option("--clock-offset-s", options.clock_offset_s,
                  "LAB TEST: the nodes' clocks read +1, -1, +2, -2, ... times this many seconds "
                  "off the machine's, as separate hosts' clocks disagree")
      ->check(cli::Real(0.0, 3600.0));
  cli::NoDefaultShown(
      run->add_option(
             "--cap-unit", options.cap_unit,
             "--hosts netns: cap what reaches this unit's host at --cap-kbit (tc tbf), the "
             "whole run")
          ->check(cli::Integer<int>(0, 1 << 20)));
  run->add_option("--cap-kbit", options.cap_kbit, "the cap of --cap-unit, kbit/s")
      ->check(cli::Integer<int>(1, 10000000));
  run->add_option("--stall-by", options.stall_by,
                  "how --stall-unit stalls: signal (SIGSTOP/SIGCONT) or link (--hosts netns: its "
                  "host's link down, then up)")
      ->check(CLI::IsMember({"signal", "link"}));
  cli::NoDefaultShown(
      run->add_option("--enroll-unit", options.enroll_unit,
                      "--hosts netns: start this unit with no site key (--enroll); the lab accepts "
                      "it as the operator would, once it asks (the report says how long it took)")
          ->check(cli::Integer<int>(0, 1 << 20)));
  cli::NoDefaultShown(
      run->add_option("--join-late", options.join_late,
                      "start this unit only once the others hold their calibration: it joins the "
                      "calibrated site (a live join; the report says whether any other unit was "
                      "recalibrated)")
          ->check(cli::Integer<int>(0, 1 << 20)));
}

// `run`'s show, blend, node and terminal flags.
void AddRunShowFlags(CLI::App* run, sim::LabRunOptions& options, std::string& progress) {
  run->add_option("--render", options.render,
                  "the nodes' show: on (grid measured from above, tracks played) or off")
      ->check(CLI::IsMember({"on", "off"}));
  run->add_option("--blend", options.blend,
                  "the nodes' blend: on (measured: raw white against blended white) or off")
      ->check(CLI::IsMember({"on", "off"}));
  run->add_option("--black-match", options.black_match,
                  "the nodes raise the black where fewer projectors overlap (measured: "
                  "photometric.black_step_pct): on or off")
      ->check(CLI::IsMember({"on", "off"}));
  run->add_option("--node-huge-pages", options.node_huge_pages,
                  "each node's heap on transparent huge pages, every thread's allocations in "
                  "it (GLIBC_TUNABLES glibc.malloc.hugetlb=1, arena_max=1: a killed node's "
                  "sockets close sooner): on or off; off where the nodes render on an NVIDIA "
                  "GPU (there they slowed a re-blend's first frame by ~30 ms)")
      ->check(CLI::IsMember({"on", "off"}));
  run->add_option("--show-s", options.show_s, "how long the show plays (s)")
      ->check(cli::Real(0.0, 3600.0));
  run->add_option("--render-max-fps", options.render_max_fps, "frames a second per node at most")
      ->check(cli::Real(0.1, 240.0));
  run->add_option("--image-width", options.image_width_px, "Width of the report's pictures (px)")
      ->check(cli::Integer<int>(16, 8192));
  run->add_option("--resolution-scale", options.resolution_scale,
                  "Every projector and camera at this fraction of its resolution (large sites on "
                  "a small machine)")
      ->check(cli::Real(0.05, 1.0));
  cli::NoDefaultShown(
      run->add_option("--device-timing", options.device_timing,
                      "every unit's device timing: ideal (a capture shows the frame last sent) or "
                      "real (60 Hz projector two frames late, 30 fps camera with a two-frame "
                      "queue, 5 % repeated and 2 % lost frames); default: the site file's")
          ->check(CLI::IsMember({"ideal", "real"})));
  run->add_option("--noise-seed", options.noise_seed,
                  "Seed of the world's capture noise (the same site with other noise)")
      ->check(cli::Integer<uint64_t>(0, UINT64_MAX));
  run->add_option("--heartbeat-ms", options.heartbeat_ms,
                  "Membership heartbeat of coordinator and nodes, ms (0: 100, or 100 x units / 16 "
                  "past 16 units)")
      ->check(cli::Integer<int>(0, 10000));
  run->add_flag("--curve", options.curve,
                "Authenticate the whole run: a site key in OUT/site.key, CURVE on world, "
                "coordinator and nodes");
  run->add_option("--hosts", options.hosts,
                  "Where the children run: local (loopback), or netns (each on a host of its own: "
                  "a network namespace on a bridge; discovery, CURVE; needs root)")
      ->check(CLI::IsMember({"local", "netns"}));
  run->add_option("--progress", progress,
                  "Terminal progress: bars, plain lines, or auto (bars "
                  "on a TTY)")
      ->check(CLI::IsMember({"auto", "bar", "plain"}));
}

void AddSweepFlags(CLI::App* sweep, sim::LabSweepOptions& sweep_options) {
  sweep->add_option("--site", sweep_options.site,
                    "Site: sandtable-3, grid-N (1..64), flat-4, random:SEED (a random sound site), "
                    "or a site file");
  sweep->add_option("--scene", sweep_options.scene, "Scene: sandtable, city, flat, or a glTF file");
  sweep->add_option("--out", sweep_options.out_dir, "Output directory (sweep.md, sweep.csv, runs/)")
      ->required();
  sweep->add_option("--seed", sweep_options.seed, "Seed of every run")
      ->check(cli::Integer<uint64_t>(0, UINT64_MAX));
  sweep->add_option("--bin-dir", sweep_options.bin_dir,
                    "Directory of sandtable-world/-coordinator/-node (as for run)");
  sweep
      ->add_option("--samples", sweep_options.metric_samples,
                   "Surface points sampled by each run's registration metric")
      ->check(cli::Integer<int>(1, 10000000));
  sweep->add_option("--only", sweep_options.only,
                    "run only these configurations (defaults, phase-steps=4, ...; repeat it)");
}

void AddScaleFlags(CLI::App* scale, sim::LabScaleOptions& scale_options) {
  scale->add_option("--nodes", scale_options.nodes, "site sizes N of grid-N, e.g. 2,4,8,16")
      ->delimiter(',')
      ->check(cli::Integer<int>(1, 64));
  scale->add_option("--scene", scale_options.scene, "Scene: city, sandtable, flat, or a glTF file");
  scale->add_option("--out", scale_options.out_dir, "Output directory (scale.md, scale.csv, runs/)")
      ->required();
  scale->add_option("--seed", scale_options.seed, "Seed of every run")
      ->check(cli::Integer<uint64_t>(0, UINT64_MAX));
  scale->add_option("--bin-dir", scale_options.bin_dir,
                    "Directory of sandtable-world/-coordinator/-node (as for run)");
  scale
      ->add_option("--samples", scale_options.metric_samples,
                   "Surface points sampled by each run's registration metric")
      ->check(cli::Integer<int>(1, 10000000));
  scale
      ->add_option("--resolution-scale", scale_options.resolution_scale,
                   "Every projector and camera at this fraction of its resolution")
      ->check(cli::Real(0.05, 1.0));
  scale->add_flag("--reblend", scale_options.reblend,
                  "with the show and the blend, unit 0 killed after calibration: the re-blend "
                  "time per N (much slower)");
}

void AddChaosFlags(CLI::App* chaos, sim::LabChaosOptions& chaos_options) {
  chaos->add_option("--site", chaos_options.site,
                    "Site: sandtable-3, grid-N (3..64), flat-4 (at least 3 units)");
  chaos->add_option("--scene", chaos_options.scene, "Scene: sandtable, city, flat, or a glTF file");
  chaos->add_option("--out", chaos_options.out_dir, "Output directory (chaos.md, chaos.csv, runs/)")
      ->required();
  chaos->add_option("--seed", chaos_options.first_seed, "Seed of the first run (then +1 each)")
      ->check(cli::Integer<uint64_t>(0, UINT64_MAX));
  chaos->add_option("--runs", chaos_options.runs, "Runs (seeds)")
      ->check(cli::Integer<int>(1, 1000));
  chaos->add_option("--bin-dir", chaos_options.bin_dir,
                    "Directory of sandtable-world/-coordinator/-node (as for run)");
  chaos
      ->add_option("--hosts", chaos_options.hosts,
                   "Where each run's children run: local, or netns (as for run; needs root)")
      ->check(CLI::IsMember({"local", "netns"}));
  chaos
      ->add_option("--samples", chaos_options.metric_samples,
                   "Surface points sampled by each run's registration metric")
      ->check(cli::Integer<int>(1, 10000000));
}

}  // namespace

static int Run(int argc, char** argv) {
  using namespace sandtable;
  SetLogTag("lab");
  CLI::App app("sandtable-lab: a simulated site on localhost, measured against the truth",
               "sandtable-lab");
  cli::Configure(app);
  app.require_subcommand(1);
  CLI::App* run = app.add_subcommand("run", "Run the site, collect calibrations, write the report");
  cli::Configure(*run);
  sim::LabRunOptions options;
  std::string progress = "auto";
  AddRunFlags(run, options);
  AddRunFaultFlags(run, options);
  AddRunShowFlags(run, options, progress);
  CLI::App* sweep = app.add_subcommand(
      "sweep", "Run time against error: one run per configuration, CSV and Pareto plots");
  cli::Configure(*sweep);
  sim::LabSweepOptions sweep_options;
  AddSweepFlags(sweep, sweep_options);
  CLI::App* scale =
      app.add_subcommand("scale", "The cost of a site as it grows: one grid-N run per N, plots");
  cli::Configure(*scale);
  sim::LabScaleOptions scale_options;
  AddScaleFlags(scale, scale_options);
  CLI::App* chaos =
      app.add_subcommand("chaos",
                         "Faults while a site runs, over seeded runs: kills, a join, a stall, the "
                         "coordinator killed and restarted, faulty links; annotations checked");
  cli::Configure(*chaos);
  sim::LabChaosOptions chaos_options;
  AddChaosFlags(chaos, chaos_options);
  CLI::App* html = app.add_subcommand(
      "html", "A markdown report as one HTML page, the PNGs it links from its folder inlined");
  cli::Configure(*html);
  std::string html_in, html_out, html_title = "Sandtable report";
  html->add_option("markdown", html_in, "the report (.md)")->required();
  html->add_option("-o,--out", html_out, "the page (default: the report's name with .html)");
  html->add_option("--title", html_title, "the page's title");
  if (std::optional<int> exit = cli::Parse(app, argc, argv)) return *exit;
  if (html->parsed()) {
    const std::filesystem::path in(html_in);
    const std::filesystem::path out = html_out.empty()
                                          ? std::filesystem::path(in).replace_extension(".html")
                                          : std::filesystem::path(html_out);
    Expected<std::string> markdown = ReadInputFile(in, kMaxTextInputBytes);
    if (!markdown.ok()) {
      std::cerr << "sandtable-lab html: " << markdown.status().ToString() << "\n";
      return 2;
    }
    const std::string dir = in.has_parent_path() ? in.parent_path().string() : ".";
    Expected<std::string> page = sim::MarkdownToHtmlPage(*markdown, dir, html_title);
    Status written = page.ok() ? WriteFileAtomically(out, *page) : page.status();
    if (!written.ok()) {
      std::cerr << "sandtable-lab html: " << out.string() << ": " << written.ToString() << "\n";
      return 1;
    }
    std::cout << "sandtable-lab html: " << out.string() << "\n";
    return 0;
  }
  if (scale->parsed() || sweep->parsed() || chaos->parsed()) {
    struct sigaction action {};
    action.sa_handler = OnSignal;
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGTERM, &action, nullptr);
    signal(SIGPIPE, SIG_IGN);
  }
  if (scale->parsed()) {
    for (int i = 0; i < argc; ++i) {
      scale_options.command_line += (i ? " " : "") + std::string(argv[i]);
    }
    return sim::RunScale(scale_options, g_stop, std::cout, std::cerr);
  }
  if (chaos->parsed()) {
    for (int i = 0; i < argc; ++i) {
      chaos_options.command_line += (i ? " " : "") + std::string(argv[i]);
    }
    return sim::RunChaos(chaos_options, g_stop, std::cout, std::cerr);
  }
  if (sweep->parsed()) {
    for (int i = 0; i < argc; ++i) {
      sweep_options.command_line += (i ? " " : "") + std::string(argv[i]);
    }
    return sim::RunSweep(sweep_options, g_stop, std::cout, std::cerr);
  }

  options.progress_tty = progress == "bar" || (progress == "auto" && isatty(STDERR_FILENO));
  options.phase_lines = !isatty(STDOUT_FILENO);
  for (int i = 0; i < argc; ++i) options.command_line += (i ? " " : "") + std::string(argv[i]);
  struct sigaction action {};
  action.sa_handler = OnSignal;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  // A closed stdout (a supervisor that went away) must not kill the lab before it tears down.
  signal(SIGPIPE, SIG_IGN);
  return sim::RunLab(options, g_stop, std::cout, std::cerr);
}

int main(int argc, char** argv) { return sandtable::GuardedMain(argc, argv, "sandtable-lab", Run); }
