// The one-line JSON readiness hand-shake of every Sandtable program (docs/architecture.md).
//
// A program that serves something prints exactly one line on stdout once it is ready, a JSON
// object whose "ready" member names the program, followed by the endpoints it bound:
//   {"ready":"sandtable-world","world":"tcp://127.0.0.1:40111"}
//   {"ready":"sandtable-coordinator","requests":"tcp://...","events":"tcp://...","status":"http://..."}
//   {"ready":"sandtable-node","id":3,"peer":"tcp://..."}
// Later state changes a supervisor may wait for use the same form with another key, e.g.
//   {"calibrated":3,"source":"factory+true_pose","json":"DIR/unit-3.json","yaml":"DIR/unit-3.yaml"}
// Supervisors (sandtable-lab, tests) parse these lines as JSON; every other line on stdout is
// free text for people.
#pragma once

#include <ostream>

#include <nlohmann/json.hpp>

namespace sandtable {

// Writes `fields` as one compact JSON line and flushes.
inline void WriteJsonLine(std::ostream& out, const nlohmann::json& fields) {
  out << fields.dump() << std::endl;
}

}  // namespace sandtable
