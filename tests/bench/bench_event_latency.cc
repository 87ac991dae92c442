// Event fan-out latency coordinator -> node over loopback TCP at 120 Hz.
//
//   build/tests/bench/bench_event_latency [EVENTS=1200] [RATE_HZ=120] [SUBSCRIBERS=1]
//   build/tests/bench/bench_event_latency --events 1200 --rate-hz 120 --subscribers 3
//
// The coordinator's real PUB path (CoordinatorServer::Publish: stamp, encode, send) publishes
// Cursor events at the given rate; each subscriber thread runs the node's receive path (SUB
// Channel: decode, validate, sequence check) and records receive time - send_time_ns. Both
// ends share one steady clock, so no clock offset enters. Prints p50, p99 and max in us.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

#include "common/cli/command_line.h"
#include "coordinator/membership/coordinator_server.h"
#include "net/channel.h"

using namespace sandtable;

int main(int argc, char** argv) {
  int events = 1200;
  double rate_hz = 120.0;
  int subscribers = 1;
  CLI::App app("Event fan-out latency coordinator -> nodes over loopback TCP.",
               "bench_event_latency");
  cli::Configure(app);
  app.add_option("--events,events", events, "events published")->check(cli::Integer(1, 10000000));
  app.add_option("--rate-hz,rate_hz", rate_hz, "publishing rate, Hz")
      ->check(cli::Real(0.1, 100000.0));
  app.add_option("--subscribers,subscribers", subscribers, "subscriber threads")
      ->check(cli::Integer(1, 256));
  if (std::optional<int> exit = cli::Parse(app, argc, argv)) return *exit;
  coordinator::CoordinatorServer server({});
  if (Status s = server.Start(); !s.ok()) {
    std::fprintf(stderr, "%s\n", s.ToString().c_str());
    return 1;
  }
  std::atomic<int> ready{0};
  std::atomic<bool> done{false};
  std::vector<std::vector<double>> latencies_us(subscribers);
  std::vector<std::thread> threads;
  for (int i = 0; i < subscribers; ++i) {
    threads.emplace_back([&, i] {
      zmq::context_t context;
      proto::MessageCounters counters;
      auto sub = net::Socket::Create(&context, net::SocketType::kEventSubscriber);
      if (!sub.ok() || !(*sub)->Connect(server.event_endpoint()).ok()) return;
      net::Channel channel(std::move(*sub), 1000 + i, 1, &counters);
      bool counted_ready = false;
      while (!done.load()) {
        std::vector<bool> readable;
        (void)net::Socket::Poll({&channel.socket()}, std::chrono::milliseconds(20), &readable);
        if (!readable[0]) continue;
        while (true) {
          auto in = channel.TryReceive();
          if (!in.ok() || !in->has_value()) break;
          const int64_t now_ns = proto::SteadyNowNs();
          const auto& e = (*in)->envelope;
          if (e.has_member_list() && !counted_ready) {
            counted_ready = true;  // subscription is live (PUB/SUB slow joiner passed)
            ++ready;
          }
          if (e.has_cursor()) latencies_us[i].push_back((now_ns - e.send_time_ns()) * 1e-3);
        }
      }
    });
  }
  // Serve until every subscriber has seen a member list.
  while (ready.load() < subscribers) (void)server.Step(std::chrono::milliseconds(10));
  const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(1.0 / rate_hz));
  auto next = std::chrono::steady_clock::now();
  for (int k = 0; k < events; ++k) {
    std::this_thread::sleep_until(next);  // the 120 Hz pacing of the event source
    next += period;
    wire::Envelope event;
    event.mutable_cursor()->set_hit(true);
    event.mutable_cursor()->mutable_hit_in_table_m()->set_x(0.001 * k);
    (void)server.Publish(std::move(event));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // let the last ones land
  done = true;
  for (auto& t : threads) t.join();
  std::vector<double> all;
  for (auto& l : latencies_us) all.insert(all.end(), l.begin(), l.end());
  if (all.empty()) {
    std::fprintf(stderr, "no events received\n");
    return 1;
  }
  std::sort(all.begin(), all.end());
  auto pct = [&](double p) { return all[std::min(all.size() - 1, size_t(p * all.size()))]; };
  std::printf(
      "event_latency rate_hz=%.0f subscribers=%d sent=%d received=%zu p50_us=%.1f "
      "p99_us=%.1f max_us=%.1f\n",
      rate_hz, subscribers, events, all.size(), pct(0.50), pct(0.99), all.back());
  return 0;
}
