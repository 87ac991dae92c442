// sandtable-node: one projector unit. Parses its flags into a NodeConfig (node/app/node_config.h)
// and runs the NodeApp (node/app/node_app.h: the devices, the runtime, the render loop and the
// services, their start and stop order).
//
//   sandtable-node [--site-config FILE] [--unit-config FILE] (docs/config-file.md; flags win)
//   sandtable-node --id N --coordinator REQUESTS,EVENTS|discover [--world ENDPOINT] [--factory
//   FILE]
//                  [--true-pose FILE] [--export-dir DIR] [--projector SPEC] [--camera SPEC]
//                  [--model FILE] [--saved-calibration FILE] [--grid-step-px N]
//                  [--calibration-path auto|full] [--expect-units N] [--phase-steps N]
//                  [--gray-cell-px X]
//                  [--bundle-iterations N] [--bundle-free all|poses]
//                  [--render auto|on|off] [--timeline TRACKS.csv] [--sun on|off]
//                  [--sun-start-h H] [--sun-hours-per-s R] [--render-max-fps F]
//                  [--render-log FILE] [--blend on|off] [--blend-step-px N]
//                  [--blend-fill-limit X] [--blend-edge-soft-mm E] [--black-match on|off]
//                  [--bind ENDPOINT] [--curve-keys FILE | --enroll FILE] [--heartbeat-ms N]
//                  [--workers N]
//                  [--fault-drop-share P] [--fault-corrupt-share P] [--fault-seed N] (lab chaos)
//   (--world E is short for --projector world:E --camera world:E; node/devices/device_factory.h)
//   sandtable-node calibrate-unit --poses DIR -o unit.json ...   (the unit's factory calibration)
//   sandtable-node render-frame --calibration unit.json -o frame.png ...  (one frame of the show)
//   sandtable-node doctor [the unit's flags]   (checks the unit's set-up:
//   node/app/doctor_command.h)
//
// On start it prints one JSON line on stdout (cluster/report_lines.h):
//   {"ready":"sandtable-node","id":3,"peer":"tcp://127.0.0.1:40123"}
// and, once it holds an exported calibration:
//   {"calibrated":3,"source":"factory+true_pose","json":"DIR/unit-3.json","yaml":"DIR/unit-3.yaml"}
// (self-calibration adds report, mpcdi, round, verified and its compute and traffic figures);
// with --saved-calibration, the check's figures first: {"verification":3,"holds":true,...}.
// On exit: {"messages":ID,"accepted":N,"rejected":N,"faults_dropped":N,"faults_corrupted":N}.
// The show (node/render, docs/render.md): once the unit holds a calibration it renders the
// --model where it stands, the annotations, the wand's cursor and the --timeline's personnel
// tracks at the coordinator's media time, under a virtual sun, into its projector; it prints
// {"render":ID,"pattern":NAME} when an operator's test pattern is first shown and a summary
// {"render":ID,"frames":N,"frame_ms_p50":...} every 2 s. --render auto renders when there is a
// projector and, when no GL context can be made, says so ({"render":ID,"unavailable":WHY}) and
// runs without a show; --render on makes that an error (exit 1).
// The blend (node/blend, docs/blend.md): with a show, once calibrated the unit blends with the
// units whose footprints overlap its own and prints {"blend":ID,"blended":true,...} each time a
// new mask is shown, {"blend":ID,"reblend":"left","peer":K,...} when a neighbour left.
// Exit status: 0 after SIGINT/SIGTERM (Goodbye said), 1 when it cannot start, 2 for a bad flag
// or a bad input file.
#include <csignal>
#include <iostream>
#include <string>

#include "cluster/report_lines.h"
#include "common/base/host_clock.h"
#include "common/base/log.h"
#include "common/base/main_guard.h"
#include "common/cli/command_line.h"
#include "common/cli/config_file.h"
#include "node/app/doctor_command.h"
#include "node/app/node_app.h"
#include "node/app/node_config.h"
#include "node/app/node_discovery.h"
#include "node/calibration/calibrate_unit_command.h"
#include "node/render/render_frame_command.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

}  // namespace

static int Run(int argc, char** argv) {
  using namespace sandtable;
  CLI::App app{"sandtable-node: one projector unit of a Sandtable site", "sandtable-node"};
  cli::Configure(app);
  app.require_subcommand(0, 1);
  CLI::App* calibrate =
      app.add_subcommand("calibrate-unit",
                         "the unit's factory calibration from chessboard + Gray-code poses "
                         "(sandtable-node calibrate-unit --help)");
  calibrate->prefix_command();  // its own parser (node/calibration/calibrate_unit_command.h)
  calibrate->set_help_flag();
  CLI::App* render_frame = app.add_subcommand(
      "render-frame", "one frame of the unit's show to a PNG (sandtable-node render-frame --help)");
  render_frame->prefix_command();  // its own parser (node/render/render_frame_command.h)
  render_frame->set_help_flag();
  CLI::App* doctor = app.add_subcommand(
      "doctor", "checks this unit's set-up and says what to fix (sandtable-node doctor --help)");
  doctor->prefix_command();  // the node's own flags (node/app/doctor_command.h)
  doctor->set_help_flag();
  node::NodeConfig config;
  node::AddNodeFlags(app, config);
  cli::AddConfigFileFlags(app, cli::ConfigProgram::kNode);
  // The site's and the unit's configuration files, read into flags the command line overrides.
  Expected<std::vector<std::string>> args = cli::ExpandConfigFiles(
      std::vector<std::string>(argv + 1, argv + argc), cli::ConfigProgram::kNode);
  if (!args.ok()) return cli::UsageError(app, args.status().message());
  if (std::optional<int> exit = cli::Parse(app, *args)) return *exit;
  if (calibrate->parsed()) return node::RunCalibrateUnit(calibrate->remaining());
  if (render_frame->parsed()) return node::RunRenderFrame(render_frame->remaining());
  if (doctor->parsed()) return node::RunDoctor(doctor->remaining());
  if (config.id != kInvalidNodeId) SetLogTag("node-" + std::to_string(config.id));
  if (config.test_clock_offset_s != 0.0) {
    SetHostClockOffsetForTest(static_cast<int64_t>(config.test_clock_offset_s * 1e9));
    ST_LOG(kWarning) << "LAB TEST: this node's clock reads " << config.test_clock_offset_s
                     << " s from the machine's (--test-clock-offset-s)";
  }

  struct sigaction action {};
  action.sa_handler = OnSignal;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);

  // A bad flag or file is a usage error (2); anything else stops the node (1).
  auto fail = [&](const Status& s) {
    if (s.code() == StatusCode::kInvalidArgument) return cli::UsageError(app, s.message());
    std::cerr << "sandtable-node: " << s.message() << "\n";
    return cli::kExitFailure;
  };
  if (config.coordinator_requests == node::kDiscover) {
    const Status found = node::DiscoverCoordinator(config, &g_stop);
    if (g_stop) return 0;
    if (!found.ok()) return fail(found);
  }
  Expected<std::unique_ptr<node::NodeApp>> node = node::NodeApp::Create(
      std::move(config),
      [](const report::ReportLine& line) { report::WriteReportLine(std::cout, line); });
  if (!node.ok()) return fail(node.status());
  return (*node)->Run(g_stop) == 0 ? 0 : cli::kExitFailure;
}

int main(int argc, char** argv) {
  return sandtable::GuardedMain(argc, argv, "sandtable-node", Run);
}
