// The projection schedule: conflict graph from the pre-pass and its colouring.
#include "node/calibration/schedule.h"

#include <gtest/gtest.h>

namespace sandtable::node {
namespace {

void ExpectProperColouring(const std::map<NodeId, std::set<NodeId>>& graph,
                           const std::map<NodeId, int>& colours) {
  ASSERT_EQ(colours.size(), graph.size());
  for (const auto& [v, neighbours] : graph) {
    for (NodeId n : neighbours) EXPECT_NE(colours.at(v), colours.at(n)) << v << " - " << n;
  }
}

TEST(Schedule, CamerasSeeingTwoProjectorsMakeThemConflict) {
  // Camera 1 sees projectors 0, 1; camera 2 sees 1, 2; projector 3 is seen by camera 3 only.
  const std::map<NodeId, std::set<NodeId>> seeing{{0, {0, 1}}, {1, {1, 2}}, {2, {2}}, {3, {3}}};
  const auto graph = ConflictGraph(seeing);
  EXPECT_EQ(graph.at(0), (std::set<NodeId>{1}));
  EXPECT_EQ(graph.at(1), (std::set<NodeId>{0, 2}));
  EXPECT_EQ(graph.at(2), (std::set<NodeId>{1}));
  EXPECT_TRUE(graph.at(3).empty());
  const auto colours = ColourGraph(graph);
  ExpectProperColouring(graph, colours);
  EXPECT_EQ(ColourCount(colours), 2);
}

TEST(Schedule, AGridNeedsColoursNotProjectors) {
  // A 4 x 4 grid of projectors; each camera sees its own footprint and its 8 neighbours'.
  std::map<NodeId, std::set<NodeId>> seeing;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      const NodeId p = static_cast<NodeId>(4 * r + c);
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const int rr = r + dr, cc = c + dc;
          if (rr >= 0 && rr < 4 && cc >= 0 && cc < 4)
            seeing[p].insert(static_cast<NodeId>(4 * rr + cc));
        }
      }
    }
  }
  const auto graph = ConflictGraph(seeing);
  const auto colours = ColourGraph(graph);
  ExpectProperColouring(graph, colours);
  // Cameras see 3 x 3 neighbourhoods, so projectors two apart conflict (5 x 5 window): at
  // most 9 colours are needed for any grid size, whatever the number of projectors.
  EXPECT_LE(ColourCount(colours), 9);
  EXPECT_LT(ColourCount(colours), 16);
  EXPECT_EQ(colours, ColourGraph(graph));  // deterministic
}

TEST(Schedule, CompleteGraphNeedsOneColourEach) {
  const std::map<NodeId, std::set<NodeId>> seeing{{0, {0, 1, 2}}, {1, {0, 1, 2}}, {2, {0, 1, 2}}};
  const auto colours = ColourGraph(ConflictGraph(seeing));
  EXPECT_EQ(ColourCount(colours), 3);
}

}  // namespace
}  // namespace sandtable::node
