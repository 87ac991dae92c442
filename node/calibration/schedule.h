// The projection schedule of a self-calibration round: projectors that no camera sees
// together may show their patterns at the same time, so the round's projection time grows with
// the number of colours of the conflict graph, not with the number of projectors.
//
// Conflict graph: projectors p and q conflict when some camera saw both in the pre-pass
// (its decoding could not tell their patterns apart). Colouring: DSatur (Brelaz 1979), every
// tie broken by the lower id, so every node that runs it on the same graph gets the same
// colours. Colours are 0, 1, 2 ...; at most max degree + 1 are used.
#pragma once

#include <map>
#include <set>
#include <vector>

#include "common/base/ids.h"

namespace sandtable::node {

// cameras_seeing[p]: the cameras that saw projector p. Returns the conflict graph (symmetric,
// every projector present as a key).
std::map<NodeId, std::set<NodeId>> ConflictGraph(
    const std::map<NodeId, std::set<NodeId>>& cameras_seeing);
// The same graph from explicit conflicting pairs (a, b) over `projectors` (pairs naming a
// projector not listed are ignored). The runner uses it with the pairs whose lit masks touch.
std::map<NodeId, std::set<NodeId>> ConflictGraphFromPairs(
    const std::set<NodeId>& projectors, const std::set<std::pair<NodeId, NodeId>>& pairs);

std::map<NodeId, int> ColourGraph(const std::map<NodeId, std::set<NodeId>>& graph);

int ColourCount(const std::map<NodeId, int>& colours);

}  // namespace sandtable::node
