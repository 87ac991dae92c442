// sandtable-coordinator: the site's rendezvous (membership), time reference and event hub.
//
//   sandtable-coordinator [--requests tcp://127.0.0.1:*] [--events tcp://127.0.0.1:*]
//                         [--curve-keys site.key] [--heartbeat-ms 100] [--misses 5]
//   sandtable-coordinator --generate-curve-keys site.key
//
// On start it prints one line on stdout, for operators and tests:
//   sandtable-coordinator requests=tcp://127.0.0.1:40001 events=tcp://127.0.0.1:40002
// SIGINT/SIGTERM stop it cleanly.
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>

#include "common/base/log.h"
#include "coordinator/membership/coordinator_server.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

int Usage(const char* why) {
  std::cerr << "sandtable-coordinator: " << why << "\n"
            << "usage: sandtable-coordinator [--requests ENDPOINT] [--events ENDPOINT]\n"
            << "         [--curve-keys FILE] [--heartbeat-ms N] [--misses N]\n"
            << "       sandtable-coordinator --generate-curve-keys FILE\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace sandtable;
  SetLogTag("coordinator");
  coordinator::CoordinatorOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (i + 1 >= argc) return Usage(("missing value after " + flag).c_str());
    const std::string value = argv[++i];
    if (flag == "--requests") {
      options.request_endpoint = value;
    } else if (flag == "--events") {
      options.event_endpoint = value;
    } else if (flag == "--curve-keys") {
      Expected<net::CurveKeyPair> keys = net::ReadCurveKeyFile(value);
      if (!keys.ok()) return Usage(keys.status().ToString().c_str());
      options.curve = *keys;
    } else if (flag == "--generate-curve-keys") {
      Expected<net::CurveKeyPair> keys = net::GenerateCurveKeyPair();
      Status written = keys.ok() ? net::WriteCurveKeyFile(value, *keys) : keys.status();
      if (!written.ok()) {
        std::cerr << written.ToString() << "\n";
        return 1;
      }
      std::cout << "wrote " << value << "\n";
      return 0;
    } else if (flag == "--heartbeat-ms") {
      options.membership.heartbeat_period = std::chrono::milliseconds(std::atoi(value.c_str()));
    } else if (flag == "--misses") {
      options.membership.misses_allowed = std::atoi(value.c_str());
    } else {
      return Usage(("unknown flag " + flag).c_str());
    }
  }
  struct sigaction action {};
  action.sa_handler = OnSignal;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);

  coordinator::CoordinatorServer server(options);
  Status started = server.Start();
  if (!started.ok()) {
    ST_LOG(kError) << "cannot start: " << started.ToString();
    return 1;
  }
  std::cout << "sandtable-coordinator requests=" << server.request_endpoint()
            << " events=" << server.event_endpoint() << std::endl;
  Status ran = server.Run(g_stop);
  ST_LOG(kInfo) << "stopping; messages " << server.counters().ToString();
  if (!ran.ok()) {
    ST_LOG(kError) << ran.ToString();
    return 1;
  }
  return 0;
}
