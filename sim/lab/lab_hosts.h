// LabHosts: the lab's children on separate hosts of one machine (`sandtable-lab run --hosts
// netns`, docs/lab.md "Across hosts").
//
// Each host is a network namespace of its own ("ip netns"), with one interface (a veth whose
// other end is a port of a bridge in the lab's own namespace) and its own IPv4 address on the
// run's /24; the bridge holds the lab's address, so the lab reaches every host and the hosts
// reach each other, broadcasts (the coordinator's discovery beacon) included. A child runs on
// its host through "ip netns exec" (which execs the program: its pid, signals and exit status
// are the program's own). Names carry the lab's pid ("stl<pid>-node-3", bridge "stb<pid>"); a
// run's namespaces and bridge are deleted when it ends, and leftovers of a lab that died are
// deleted by the next run. Link faults: a host's link down and up (ip link), its bandwidth
// capped (tc tbf). Needs root and iproute2; Create says why when it cannot.
// Not thread-safe (the lab's thread).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "common/base/status.h"

namespace sandtable::sim {

class NetnsHosts {
 public:
  // The bridge and the lab's address on it. Deletes what dead labs left behind first.
  static Expected<std::unique_ptr<NetnsHosts>> Create();
  ~NetnsHosts();
  NetnsHosts(const NetnsHosts&) = delete;
  NetnsHosts& operator=(const NetnsHosts&) = delete;

  // A new host named `name` ("world", "coordinator", "node-3"); its address.
  Expected<std::string> AddHost(const std::string& name);
  // `argv` run on host `name` (as given when it is not a host).
  std::vector<std::string> Wrap(const std::string& name, std::vector<std::string> argv) const;
  // The host's address ("" when it is not a host), and the lab's own.
  std::string Address(const std::string& name) const;
  const std::string& lab_address() const { return lab_address_; }
  // "tcp://0.0.0.0:PORT" or "tcp://*:PORT" as printed by a program bound to every interface
  // of host `name`, with that host's address instead.
  std::string Reachable(const std::string& name, const std::string& endpoint) const;

  // The host's link (its port on the bridge) down or up: the host is cut off from every other.
  Status SetLink(const std::string& name, bool up);
  // Caps what the host's link carries towards the host at `kbit_per_s` (tc tbf on the port).
  Status CapBandwidth(const std::string& name, int kbit_per_s);

 private:
  struct Host {
    std::string name, netns, port, address;
  };
  NetnsHosts(std::string bridge, std::string prefix, std::string subnet);
  const Host* Find(const std::string& name) const;

  std::string ip_;      // iproute2's ip, full path
  std::string bridge_;  // "stb<pid>"
  std::string prefix_;  // "stl<pid>-"
  std::string subnet_;  // "10.250.N." (a /24)
  std::string lab_address_;
  std::vector<Host> hosts_;
};

}  // namespace sandtable::sim
