// sandtable-node: one projector unit. This issue brings up its network side: membership with
// the coordinator, clock offset, and the peer mesh.
//
//   sandtable-node --id N --coordinator REQUESTS_ENDPOINT,EVENTS_ENDPOINT
//                  [--bind tcp://127.0.0.1:*] [--curve-keys site.key] [--heartbeat-ms 100]
//
//   sandtable-node calibrate-unit --poses DIR -o unit.json [--report report.json] ...
//     the unit (factory) calibration; see node/calibration/calibrate_unit_command.h.
//
// On start it prints one line on stdout, for operators and tests:
//   sandtable-node id=3 peer=tcp://127.0.0.1:40123
// SIGINT/SIGTERM: says Goodbye to the coordinator and exits 0.
#include <csignal>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "common/base/log.h"
#include "node/calibration/calibrate_unit_command.h"
#include "node/net/node_runtime.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

int Usage(const std::string& why) {
  std::cerr
      << "sandtable-node: " << why << "\n"
      << "usage: sandtable-node --id N --coordinator REQUESTS,EVENTS [--bind ENDPOINT]\n"
      << "         [--curve-keys FILE] [--heartbeat-ms N]\n"
      << "       sandtable-node calibrate-unit --poses DIR -o unit.json [--report FILE] ...\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace sandtable;
  if (argc >= 2 && std::string(argv[1]) == "calibrate-unit") {
    return node::RunCalibrateUnit(std::vector<std::string>(argv + 2, argv + argc));
  }
  node::NodeOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (i + 1 >= argc) return Usage("missing value after " + flag);
    const std::string value = argv[++i];
    if (flag == "--id") {
      char* end = nullptr;
      const unsigned long id = std::strtoul(value.c_str(), &end, 10);
      if (end == value.c_str() || *end != '\0' || id >= kInvalidNodeId) {
        return Usage("--id must be a number below " + std::to_string(kInvalidNodeId));
      }
      options.id = static_cast<NodeId>(id);
    } else if (flag == "--coordinator") {
      const size_t comma = value.find(',');
      if (comma == std::string::npos) return Usage("--coordinator needs REQUESTS,EVENTS");
      options.coordinator_requests = value.substr(0, comma);
      options.coordinator_events = value.substr(comma + 1);
    } else if (flag == "--bind") {
      options.peer_bind = value;
    } else if (flag == "--curve-keys") {
      Expected<net::CurveKeyPair> keys = net::ReadCurveKeyFile(value);
      if (!keys.ok()) return Usage(keys.status().ToString());
      options.curve = *keys;
    } else if (flag == "--heartbeat-ms") {
      options.heartbeat_period = std::chrono::milliseconds(std::atoi(value.c_str()));
    } else {
      return Usage("unknown flag " + flag);
    }
  }
  SetLogTag("node-" + std::to_string(options.id));
  struct sigaction action {};
  action.sa_handler = OnSignal;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);

  node::NodeRuntime runtime(options);
  Status started = runtime.Start();
  if (!started.ok()) {
    ST_LOG(kError) << "cannot start: " << started.ToString();
    return 1;
  }
  std::cout << "sandtable-node id=" << options.id << " peer=" << runtime.peer_endpoint()
            << std::endl;
  Status ran = runtime.Run(g_stop);
  if (auto offset = runtime.clock_offset()) {
    ST_LOG(kInfo) << "clock offset to coordinator " << offset->offset_s * 1e3
                  << " ms, error <= " << offset->error_bound_s * 1e3 << " ms over "
                  << offset->samples << " samples";
  }
  ST_LOG(kInfo) << "stopping; messages " << runtime.counters().ToString();
  return ran.ok() ? 0 : 1;
}
