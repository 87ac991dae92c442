// `sandtable-coordinator enrollment`: the operator's side of accepting a new unit (docs/deploy.md,
// "Accepting a new unit"). Connects to the serving coordinator's requests socket with the site's
// key (so only someone who holds it can decide), lists the units that ask to join and, with
// --accept or --refuse, decides on one of them by its fingerprint (the one the unit logs).
//
//   sandtable-coordinator enrollment --requests tcp://127.0.0.1:7000 --curve-keys site.keys
//                                    [--accept FINGERPRINT | --refuse FINGERPRINT] [--json]
//
// Exit 0 when the list (and the decision) came back; 1 when the coordinator did not answer
// within --timeout-ms or refused the decision (no such unit, enrollment off); 2 for a bad flag.
#pragma once

#include <string>
#include <vector>

namespace sandtable::coordinator {

// `args` are the arguments after "enrollment".
int RunEnrollmentCommand(const std::vector<std::string>& args);

}  // namespace sandtable::coordinator
