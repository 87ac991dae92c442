// sandtable-coordinator: the site's rendezvous (membership), time reference and event hub.
//
//   sandtable-coordinator [--requests tcp://127.0.0.1:*] [--events tcp://127.0.0.1:*]
//                         [--curve-keys site.key | --insecure] [--heartbeat-ms 100] [--misses 5]
//                         [--annotations FILE.db] [--annotation-sync full|normal]
//                         [--export-session FILE.jsonl | --import-session FILE.jsonl]
//                         [--timeline TRACKS.csv] [--status PORT|IPv4:PORT]
//                         [--status-token-file FILE] [--max-members 256]
//                         [--tracker-replay FILE.traj|FILE.csv [--table-from-tracker FILE.json]
//                          | --virtual-wand SCRIPT.txt] [--scene SCENE.gltf|SCENE.glb]
//                         [--beacon 5670 [--site-name NAME]]  (LAN discovery, net/discovery.h)
//   sandtable-coordinator --site-config site.json [flags that win over it] (docs/config-file.md)
//   sandtable-coordinator --generate-curve-keys site.key
//   sandtable-coordinator enrollment --requests ENDPOINT --curve-keys site.key
//                         [--accept FINGERPRINT | --refuse FINGERPRINT]
//     (the units that ask to join, and the operator's decision: docs/deploy.md, "Accepting a
//      new unit"; --enroll ENDPOINT on the serving coordinator takes their requests)
//
// Flags are parsed by CLI11 (common/cli/command_line.h): --help lists them all; a bad value
// (--heartbeat-ms abc, --misses 0, --status 99999) or flags that exclude each other exit 2
// with a message naming the flag. A file that does not load (bad input) exits 2; an internal
// failure (cannot bind, cannot write) exits 1, and so does an escaped exception (GuardedMain).
//
// --annotations: the SQLite database of annotation events (created when absent). Without it
// annotations live in memory only (a warning says so). A damaged database, a changed row, a
// log shorter than its sequence record (a lost -wal) or a database another coordinator holds:
// it refuses to start, says why and how to recover (exit code 2; docs/reliability.md);
// --annotations-accept-loss accepts lost events explicitly. --export-session / --import-session
// work on the database and exit (docs/coordinator.md); a bad session file exits 2 naming the
// line and field and imports nothing.
//
// Test patterns (docs/render.md): test_pattern_request on the ROUTER, site-wide or per node,
// published as test_pattern_state. Recalibration (docs/console.md): recalibrate_request on the
// ROUTER, for the site or one member, published as recalibrate_ask.
// --timeline: personnel tracks (CSV, docs/coordinator.md) replayed with play/pause/seek/rate
// requests and a timeline_clock on the events socket. --status: JSON at http://HOST:PORT/status
// (port 0: any free port; a bare PORT binds loopback). --status-token-file: a token (one
// line, 16..256 printable characters, file mode 0600) every status request must send as
// "Authorization: Bearer TOKEN"; required with --curve-keys and for any address beyond loopback
// (exit 2 otherwise). --max-members: the site's size; Hellos past it are refused (default 256).
// Limits against hostile peers: docs/reliability.md.
//
// --tracker-replay: replays a recorded tracker trajectory (FASTRAK .traj at 100 Hz, or the CSV
// of docs/tracker-formats.md) in real time from the start, publishing tracker_pose and cursor
// events per sample (coordinator/wand/wand_service.h); --table-from-tracker: the calibration
// as JSON {"rotation_wxyz": [...], "translation_m": [...]} (identity without it).
// --virtual-wand: plays a scripted wand (coordinator/tracker/virtual_wand.h, format in
// docs/tracker-formats.md) written in the table frame (so no --table-from-tracker); exclusive
// with --tracker-replay. With either source the wand button paints: strokes, the rim palette,
// spot eraser and clear go through the annotation service (persisted before published).
// --scene: the glTF scene (table frame after the +y-up -> +z-up conversion, docs/frames.md) the
// wand ray is cast against, in addition to the table plane z = 0.
//
// Once serving it prints one JSON line on stdout (cluster/report_lines.h), for supervisors
// and tests:
//   {"ready":"sandtable-coordinator","requests":"tcp://127.0.0.1:40001",
//    "events":"tcp://127.0.0.1:40002"}
// with "status":"http://127.0.0.1:PORT/status" added when --status is given.
// SIGINT/SIGTERM stop it cleanly.
#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <string>

#include "cluster/report_lines.h"
#include "common/base/log.h"
#include "common/base/main_guard.h"
#include "common/cli/command_line.h"
#include "common/cli/config_file.h"
#include "common/scene/gltf_loader.h"
#include "coordinator/annotations/annotation_service.h"
#include "coordinator/annotations/session_file.h"
#include "coordinator/calibration/recalibration_service.h"
#include "coordinator/display/test_pattern_service.h"
#include "coordinator/membership/coordinator_server.h"
#include "coordinator/membership/enrollment_command.h"
#include "coordinator/status/console_actions.h"
#include "coordinator/status/http_status_server.h"
#include "coordinator/status/status_service.h"
#include "coordinator/timeline/timeline_service.h"
#include "coordinator/tracker/replay_source.h"
#include "coordinator/tracker/virtual_wand.h"
#include "coordinator/wand/wand_service.h"
#include "net/discovery.h"
#include "net/endpoint.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

using namespace sandtable;  // this file's helpers, like Run

// Everything the command line sets.
struct CoordinatorFlags {
  coordinator::CoordinatorOptions options;
  std::string annotations_path = ":memory:";
  coordinator::AnnotationStoreOptions store_options;
  std::string export_path, import_path, timeline_path, status_address;
  std::string tracker_replay_path, table_from_tracker_path, virtual_wand_path, scene_path;
  std::string curve_keys_path, generate_keys_path, sync_name = "full", status_token_path;
  int beacon_port = 0;  // the LAN beacon's UDP port (0: no beacon)
  std::string site_name = "sandtable";
  int heartbeat_ms = static_cast<int>(options.membership.heartbeat_period.count());
  int misses = options.membership.misses_allowed;
};

// The flags, into `f`; returns --generate-curve-keys (a command of its own).
CLI::Option* AddFlags(CLI::App& app, CoordinatorFlags& f) {
  cli::Configure(app);
  app.add_option("--requests", f.options.request_endpoint, "ROUTER endpoint the nodes connect to")
      ->check(cli::Endpoint());
  app.add_option("--events", f.options.event_endpoint,
                 "endpoint of the events (subscribers connect to it)")
      ->check(cli::Endpoint());
  app.add_option("--curve-keys", f.curve_keys_path, "site CURVE key file: require CURVE");
  app.add_option("--beacon", f.beacon_port,
                 "broadcast the site's beacon on this UDP port (5670 is the nodes' default), so "
                 "that nodes started with --coordinator discover find it; needs --requests and "
                 "--events beyond loopback")
      ->check(cli::Integer(1, 65535));
  app.add_option("--site-name", f.site_name, "the site's name in its beacon");
  app.add_option("--enroll", f.options.enroll_endpoint,
                 "where units without the site's key ask to be accepted (an operator decides with "
                 "`sandtable-coordinator enrollment`); its port goes into the beacon; needs "
                 "--curve-keys")
      ->check(cli::Endpoint());
  app.add_flag("--insecure", f.options.insecure,
               "allow --requests/--events beyond loopback without --curve-keys (an open site: "
               "anyone on the network may join it; logged every minute)");
  CLI::Option* generate = app.add_option("--generate-curve-keys", f.generate_keys_path,
                                         "write a new site key file and exit");
  app.add_option("--heartbeat-ms", f.heartbeat_ms, "heartbeat period of the members, ms")
      ->check(cli::Integer(1, 60000));
  app.add_option("--misses", f.misses, "missed heartbeats before a member is dead")
      ->check(cli::Integer(1, 1000));
  app.add_option("--annotations", f.annotations_path,
                 "SQLite database of the annotation events (created when absent; default: in "
                 "memory only)");
  app.add_option("--annotation-sync", f.sync_name, "SQLite synchronous mode of the database")
      ->check(CLI::IsMember({"full", "normal"}));
  app.add_flag("--annotations-accept-loss", f.store_options.accept_lost_events,
               "start even though acknowledged annotation events are missing (lost -wal, "
               "older copy): logged, and the sequence record reset");
  CLI::Option* export_session = app.add_option(
      "--export-session", f.export_path, "write the database's events as JSON lines and exit");
  CLI::Option* import_session = app.add_option("--import-session", f.import_path,
                                               "append JSON-lines events to the database and exit");
  export_session->excludes(import_session);
  app.add_option("--timeline", f.timeline_path, "personnel tracks (CSV) replayed as a timeline");
  app.add_option("--status", f.status_address,
                 "serve JSON at http://HOST:PORT/status (a bare PORT binds loopback; 0: any "
                 "free port)")
      ->check(CLI::Validator(
          [](std::string& value) {
            const Status valid = coordinator::HttpStatusServer::CheckAddress(value);
            return valid.ok() ? std::string() : valid.message();
          },
          "PORT|IPv4:PORT", "StatusAddress"));
  app.add_option("--status-token-file", f.status_token_path,
                 "token file for --status (required with --curve-keys or beyond loopback)");
  app.add_option("--max-members", f.options.membership.max_members,
                 "most members of the site; further Hellos are refused")
      ->check(cli::Integer(1, coordinator::kMaxMembersLimit));
  CLI::Option* replay = app.add_option("--tracker-replay", f.tracker_replay_path,
                                       "replay a tracker recording (FASTRAK .traj or .csv)");
  CLI::Option* table_from_tracker_option =
      app.add_option("--table-from-tracker", f.table_from_tracker_path,
                     "tracker calibration JSON for --tracker-replay (identity without it)");
  CLI::Option* virtual_wand = app.add_option("--virtual-wand", f.virtual_wand_path,
                                             "play a scripted wand (written in the table frame)");
  table_from_tracker_option->needs(replay);
  virtual_wand->excludes(replay)->excludes(table_from_tracker_option);
  app.add_option("--scene", f.scene_path, "glTF scene the wand ray is cast against (.gltf, .glb)");
  return generate;
}

// --import-session / --export-session: the database's events from or into a file; the exit code.
int ImportOrExport(const CoordinatorFlags& f, coordinator::AnnotationStore* store) {
  Expected<size_t> n = 0;
  if (!f.import_path.empty()) {
    // A bad file is bad input (exit 2); a failure to store it is not (exit 1).
    Expected<std::vector<wire::AnnotationEvent>> events =
        coordinator::ReadSessionFile(f.import_path);
    if (!events.ok()) {
      std::cerr << "sandtable-coordinator: --import-session: " << events.status().ToString()
                << "\n";
      return 2;
    }
    n = coordinator::ImportEvents(std::move(*events), f.import_path, store);
  } else {
    n = coordinator::ExportSession(*store, f.export_path);
  }
  if (!n.ok()) {
    std::cerr << "sandtable-coordinator: " << n.status().ToString() << "\n";
    return n.status().code() == StatusCode::kInvalidArgument ? 2 : 1;
  }
  std::cout << (f.import_path.empty() ? "exported " : "imported ") << *n << " events\n";
  return 0;
}

// The wand (--virtual-wand or --tracker-replay, cast against --scene), none without either;
// 0, or the exit code of a bad input file. Steps the server faster for a tracker's rate.
int MakeWand(CoordinatorFlags& f, std::unique_ptr<coordinator::WandService>* wand_out) {
  std::unique_ptr<coordinator::WandService> wand;
  // The wand's scene: the table plane (always) plus the glTF scene's triangles.
  std::vector<Eigen::Vector3d> scene_positions_in_table_m;
  std::vector<Eigen::Vector3i> scene_triangles;
  if (!f.scene_path.empty()) {
    Expected<Scene> scene = LoadGltfScene(f.scene_path);
    if (!scene.ok()) {
      std::cerr << "sandtable-coordinator: --scene: " << scene.status().ToString() << "\n";
      return 2;  // bad input file
    }
    for (const Eigen::Vector3f& p : scene->positions_in_table_m) {
      scene_positions_in_table_m.push_back(p.cast<double>());
    }
    scene_triangles = scene->triangles;
    ST_LOG(kInfo) << "scene: " << f.scene_path << ", " << scene->NumTriangles() << " triangles";
  }
  auto make_wand = [&](std::unique_ptr<coordinator::TrackerSource> source,
                       coordinator::WandServiceOptions wand_options) {
    return std::make_unique<coordinator::WandService>(std::move(source), wand_options,
                                                      scene_positions_in_table_m, scene_triangles);
  };
  if (!f.virtual_wand_path.empty()) {
    Expected<coordinator::VirtualWandScript> script =
        coordinator::LoadVirtualWandScript(f.virtual_wand_path);
    if (!script.ok()) {
      std::cerr << "sandtable-coordinator: --virtual-wand: " << script.status().ToString() << "\n";
      return 2;  // bad input file (docs/reliability.md)
    }
    auto source = std::make_unique<coordinator::VirtualWandSource>(f.virtual_wand_path, *script);
    ST_LOG(kInfo) << "tracker: " << source->Describe();
    wand = make_wand(std::move(source), coordinator::WandServiceOptions{});
    f.options.step_period = std::min(f.options.step_period, std::chrono::milliseconds(5));
  }
  if (!f.tracker_replay_path.empty()) {
    const bool csv =
        f.tracker_replay_path.size() >= 4 &&
        f.tracker_replay_path.compare(f.tracker_replay_path.size() - 4, 4, ".csv") == 0;
    Expected<std::vector<coordinator::TrackerSample>> samples =
        csv ? coordinator::LoadTrackerCsv(f.tracker_replay_path)
            : coordinator::LoadFastrakTraj(f.tracker_replay_path);
    if (!samples.ok()) {
      std::cerr << "sandtable-coordinator: --tracker-replay: " << samples.status().ToString()
                << "\n";
      return 2;  // bad input file (docs/reliability.md)
    }
    coordinator::WandServiceOptions wand_options;
    if (!f.table_from_tracker_path.empty()) {
      Expected<Rigid3d> table_from_tracker =
          coordinator::LoadTableFromTracker(f.table_from_tracker_path);
      if (!table_from_tracker.ok()) {
        std::cerr << "sandtable-coordinator: --table-from-tracker: "
                  << table_from_tracker.status().ToString() << "\n";
        return 2;  // bad input file
      }
      wand_options.table_from_tracker = *table_from_tracker;
    }
    auto source =
        std::make_unique<coordinator::ReplaySource>(f.tracker_replay_path, std::move(*samples));
    ST_LOG(kInfo) << "tracker: " << source->Describe();
    wand = make_wand(std::move(source), wand_options);
    // Samples go out when due, at most one step late: step at least twice per sample period
    // (5 ms for 100 Hz).
    f.options.step_period = std::min(f.options.step_period, std::chrono::milliseconds(5));
  }
  *wand_out = std::move(wand);
  return 0;
}

// The key files read (CURVE, status token) and the flags checked against each other: an exit
// code when the program must stop (a usage error, already printed).
std::optional<int> ReadKeysAndCheck(const CLI::App& app, CoordinatorFlags& f,
                                    sandtable::coordinator::HttpStatusOptions* status_options) {
  using namespace sandtable;
  if (!f.curve_keys_path.empty()) {
    Expected<net::CurveKeyPair> keys = net::ReadCurveKeyFile(f.curve_keys_path);
    if (!keys.ok()) return cli::UsageError(app, "--curve-keys: " + keys.status().ToString());
    f.options.curve = *keys;
  }
  if (!f.status_token_path.empty()) {
    Expected<std::string> token = coordinator::LoadStatusToken(f.status_token_path);
    if (!token.ok())
      return cli::UsageError(app, "--status-token-file: " + token.status().ToString());
    status_options->token = *token;
  }
  if (!f.status_address.empty() && status_options->token.empty()) {
    if (f.options.curve) {
      return cli::UsageError(app,
                             "--status on a CURVE site (--curve-keys) needs --status-token-file");
    }
    if (!coordinator::IsLoopbackAddress(f.status_address)) {
      return cli::UsageError(app, "--status " + f.status_address +
                                      " is beyond loopback: it needs --status-token-file");
    }
  }
  for (const std::string* endpoint : {&f.options.request_endpoint, &f.options.event_endpoint}) {
    if (!f.options.curve && !f.options.insecure && net::BeyondLoopback(*endpoint)) {
      return cli::UsageError(app, *endpoint +
                                      " is beyond loopback: it needs --curve-keys (or --insecure "
                                      "for an open site anyone on the network may join)");
    }
  }
  if (!f.options.enroll_endpoint.empty() && !f.options.curve) {
    return cli::UsageError(
        app, "--enroll needs --curve-keys: an accepted unit is handed the site's key");
  }
  if (f.beacon_port > 0 && !(net::BeyondLoopback(f.options.request_endpoint) &&
                             net::BeyondLoopback(f.options.event_endpoint))) {
    return cli::UsageError(app,
                           "--beacon: --requests and --events must listen beyond loopback, or "
                           "the nodes that hear the beacon cannot reach them");
  }
  return std::nullopt;
}

// The LAN beacon (--beacon): the site's name, the ports the server bound and its CURVE key.
sandtable::Expected<std::unique_ptr<sandtable::net::BeaconPublisher>> StartBeacon(
    const CoordinatorFlags& f, const sandtable::coordinator::CoordinatorServer& server) {
  using namespace sandtable;
  net::SiteBeacon site;
  site.site = f.site_name;
  if (f.options.curve) site.curve_key = f.options.curve->public_key_z85;
  const std::optional<net::TcpEndpoint> requests = net::ParseTcpEndpoint(server.request_endpoint());
  const std::optional<net::TcpEndpoint> events = net::ParseTcpEndpoint(server.event_endpoint());
  site.requests_port = requests ? std::atoi(requests->port.c_str()) : 0;
  site.events_port = events ? std::atoi(events->port.c_str()) : 0;
  if (!server.enroll_endpoint().empty()) {
    const std::optional<net::TcpEndpoint> enroll = net::ParseTcpEndpoint(server.enroll_endpoint());
    site.enroll_port = enroll ? std::atoi(enroll->port.c_str()) : 0;
  }
  Expected<std::unique_ptr<net::BeaconPublisher>> beacon =
      net::BeaconPublisher::Start(f.beacon_port, site);
  if (beacon.ok()) {
    ST_LOG(kInfo) << "beacon: site " << site.site << " on UDP port " << f.beacon_port << " from "
                  << (*beacon)->host() << " (" << (site.curve_key.empty() ? "open" : "CURVE")
                  << ")";
  }
  return beacon;
}

}  // namespace

static int Run(int argc, char** argv) {
  using namespace sandtable;
  SetLogTag("coordinator");
  CoordinatorFlags f;

  CLI::App app(
      "The site's rendezvous (membership), time reference and event hub. Prints one JSON "
      "line {\"ready\":\"sandtable-coordinator\",...} on stdout once serving; SIGINT/SIGTERM "
      "stop it.",
      "sandtable-coordinator");
  CLI::Option* generate = AddFlags(app, f);
  cli::AddConfigFileFlags(app, cli::ConfigProgram::kCoordinator);
  app.require_subcommand(0, 1);
  CLI::App* enrollment = app.add_subcommand(
      "enrollment",
      "the units that ask to join, accept or refuse one (sandtable-coordinator enrollment --help)");
  enrollment->prefix_command();  // its own parser (coordinator/membership/enrollment_command.h)
  enrollment->set_help_flag();
  // The site's configuration file, read into flags the command line overrides.
  Expected<std::vector<std::string>> args = cli::ExpandConfigFiles(
      std::vector<std::string>(argv + 1, argv + argc), cli::ConfigProgram::kCoordinator);
  if (!args.ok()) return cli::UsageError(app, args.status().message());
  if (std::optional<int> exit = cli::Parse(app, *args)) return *exit;
  if (enrollment->parsed()) return coordinator::RunEnrollmentCommand(enrollment->remaining());
  if (generate->count() > 0) {
    Expected<net::CurveKeyPair> keys = net::GenerateCurveKeyPair();
    Status written =
        keys.ok() ? net::WriteCurveKeyFile(f.generate_keys_path, *keys) : keys.status();
    if (!written.ok()) {
      std::cerr << written.ToString() << "\n";
      return 1;
    }
    std::cout << "wrote " << f.generate_keys_path << "\n";
    return 0;
  }
  coordinator::HttpStatusOptions status_options;
  if (std::optional<int> exit = ReadKeysAndCheck(app, f, &status_options)) return *exit;
  f.options.membership.heartbeat_period = std::chrono::milliseconds(f.heartbeat_ms);
  f.options.membership.misses_allowed = f.misses;
  f.store_options.sync =
      f.sync_name == "full" ? coordinator::SyncMode::kFull : coordinator::SyncMode::kNormal;
  Expected<std::unique_ptr<coordinator::AnnotationStore>> store =
      coordinator::AnnotationStore::Open(f.annotations_path, f.store_options);
  if (!store.ok()) {
    std::cerr << "sandtable-coordinator: cannot open annotations: " << store.status().ToString()
              << "\n";
    return store.status().code() == StatusCode::kInternal ? 1 : 2;
  }
  if (f.annotations_path == ":memory:") {
    ST_LOG(kWarning) << "annotations are kept in memory only (no --annotations FILE): a restart "
                        "loses them";
  } else {
    ST_LOG(kInfo) << "annotations: " << f.annotations_path << ", " << (*store)->events_loaded()
                  << " events restored, " << (*store)->state().strokes().size() << " strokes";
  }
  if (!f.import_path.empty() || !f.export_path.empty()) return ImportOrExport(f, store->get());
  coordinator::AnnotationService annotations(store->get());
  std::unique_ptr<coordinator::TimelineService> timeline;
  if (!f.timeline_path.empty()) {
    Expected<cluster::PersonnelTracks> tracks = cluster::PersonnelTracks::Load(f.timeline_path);
    if (!tracks.ok()) {
      std::cerr << "sandtable-coordinator: --timeline: " << tracks.status().ToString() << "\n";
      return 2;  // bad input file
    }
    ST_LOG(kInfo) << "timeline: " << f.timeline_path << ", " << tracks->tracks().size()
                  << " tracks, " << tracks->sample_count() << " samples, " << tracks->duration_s()
                  << " s";
    timeline = std::make_unique<coordinator::TimelineService>(std::move(*tracks));
    // The clock goes out at 30 Hz: the server must step at least that often.
    f.options.step_period = std::min(f.options.step_period, std::chrono::milliseconds(10));
  }
  std::unique_ptr<coordinator::WandService> wand;
  if (int exit = MakeWand(f, &wand); exit != 0) return exit;
  if (wand) wand->EnablePainting(coordinator::WandPainterOptions{}, &annotations);
  coordinator::TestPatternService test_patterns;
  coordinator::RecalibrationService recalibration;
  std::unique_ptr<coordinator::HttpStatusServer> http;
  std::unique_ptr<coordinator::StatusService> status;
  if (!f.status_address.empty()) {
    Expected<std::unique_ptr<coordinator::HttpStatusServer>> started =
        coordinator::HttpStatusServer::Start(f.status_address, status_options);
    if (!started.ok()) {
      std::cerr << "sandtable-coordinator: --status: " << started.status().ToString() << "\n";
      return 1;
    }
    http = std::move(*started);
    status = std::make_unique<coordinator::StatusService>(
        http.get(), coordinator::StatusSources{&annotations, timeline.get(), wand.get(),
                                               &test_patterns, &recalibration});
  }

  struct sigaction action {};
  action.sa_handler = OnSignal;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);

  coordinator::CoordinatorServer server(f.options);
  server.AddService(&annotations);
  server.AddService(&test_patterns);
  server.AddService(&recalibration);
  if (timeline) server.AddService(timeline.get());
  if (wand) server.AddService(wand.get());
  if (status) server.AddService(status.get());
  Status started = server.Start();
  if (!started.ok()) {
    ST_LOG(kError) << "cannot start: " << started.ToString();
    return 1;
  }
  std::unique_ptr<net::BeaconPublisher> beacon;
  if (f.beacon_port > 0) {
    Expected<std::unique_ptr<net::BeaconPublisher>> started_beacon = StartBeacon(f, server);
    if (!started_beacon.ok()) {
      ST_LOG(kError) << "--beacon: " << started_beacon.status().ToString();
      return 1;
    }
    beacon = std::move(*started_beacon);
  }
  report::CoordinatorReady ready{server.request_endpoint(), server.event_endpoint(), ""};
  if (http) {
    http->Publish(status->BuildJson(server));  // served before the first step
    ready.status = http->url();
    // The console's actions go to the requests socket like any operator's requests.
    auto actions =
        std::make_shared<coordinator::ConsoleActions>(server.request_endpoint(), f.options.curve);
    http->SetActionHandler([actions](const std::string& body) { return actions->Handle(body); });
  }
  report::WriteReportLine(std::cout, ready);
  Status ran = server.Run(g_stop);
  ST_LOG(kInfo) << "stopping; messages " << server.counters().ToString();
  if (!ran.ok()) {
    ST_LOG(kError) << ran.ToString();
    return 1;
  }
  return 0;
}

int main(int argc, char** argv) {
  return sandtable::GuardedMain(argc, argv, "sandtable-coordinator", Run);
}
