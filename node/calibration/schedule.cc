#include "node/calibration/schedule.h"

#include <algorithm>

namespace sandtable::node {

std::map<NodeId, std::set<NodeId>> ConflictGraphFromPairs(
    const std::set<NodeId>& projectors, const std::set<std::pair<NodeId, NodeId>>& pairs) {
  std::map<NodeId, std::set<NodeId>> graph;
  for (NodeId p : projectors) graph[p];
  for (const auto& [a, b] : pairs) {
    if (a != b && projectors.count(a) && projectors.count(b)) {
      graph[a].insert(b);
      graph[b].insert(a);
    }
  }
  return graph;
}

std::map<NodeId, std::set<NodeId>> ConflictGraph(
    const std::map<NodeId, std::set<NodeId>>& cameras_seeing) {
  std::set<NodeId> projectors;
  std::map<NodeId, std::vector<NodeId>> seen_by_camera;
  for (const auto& [p, cameras] : cameras_seeing) {
    projectors.insert(p);
    for (NodeId c : cameras) seen_by_camera[c].push_back(p);
  }
  std::set<std::pair<NodeId, NodeId>> pairs;
  for (const auto& [c, seen] : seen_by_camera) {
    for (NodeId a : seen) {
      for (NodeId b : seen) pairs.insert({a, b});
    }
  }
  return ConflictGraphFromPairs(projectors, pairs);
}

std::map<NodeId, int> ColourGraph(const std::map<NodeId, std::set<NodeId>>& graph) {
  std::map<NodeId, int> colour;
  while (colour.size() < graph.size()) {
    // Uncoloured vertex with the most distinct neighbour colours (saturation), then the
    // highest degree among the uncoloured, then the lowest id.
    NodeId best = kInvalidNodeId;
    int best_saturation = -1, best_degree = -1;
    for (const auto& [v, neighbours] : graph) {
      if (colour.count(v)) continue;
      std::set<int> seen;
      int degree = 0;
      for (NodeId n : neighbours) {
        if (auto it = colour.find(n); it != colour.end()) {
          seen.insert(it->second);
        } else {
          ++degree;
        }
      }
      const int saturation = static_cast<int>(seen.size());
      if (saturation > best_saturation || (saturation == best_saturation && degree > best_degree)) {
        best = v;
        best_saturation = saturation;
        best_degree = degree;
      }
    }
    std::set<int> used;
    for (NodeId n : graph.at(best)) {
      if (auto it = colour.find(n); it != colour.end()) used.insert(it->second);
    }
    int c = 0;
    while (used.count(c)) ++c;
    colour[best] = c;
  }
  return colour;
}

int ColourCount(const std::map<NodeId, int>& colours) {
  int count = 0;
  for (const auto& [v, c] : colours) count = std::max(count, c + 1);
  return count;
}

}  // namespace sandtable::node
