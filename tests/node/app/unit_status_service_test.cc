// UnitStatusService: what the node's lines and its calibration put into the status the console
// shows (the footprint itself: tests/common/estimation/footprint_test.cc).
#include <gtest/gtest.h>

#include "common/estimation/footprint.h"
#include "node/app/unit_status_service.h"

namespace sandtable::node {
namespace {

// 1000 x 500 projector, f = 1000 px, 2 m above the table looking straight down, its image's
// right along the table's +x and its image's down along -y: the image covers x in [-1, 1],
// y in [-0.5, 0.5].
CameraModel Projector() { return CameraModel(1000, 500, 1000.0, 1000.0, 499.5, 249.5); }
Rigid3d LookingDown() {
  return Rigid3d(Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal().toDenseMatrix(),
                 Eigen::Vector3d(0.0, 0.0, 2.0));
}

TEST(UnitStatusServiceTest, LinesAndCalibrationFillTheStatus) {
  UnitStatusService service("host-a");
  EXPECT_EQ(service.Snapshot().phase(), "starting");
  EXPECT_EQ(service.Snapshot().host_name(), "host-a");
  UnitCalibration calibration;
  calibration.projector = Projector();
  calibration.table_from_projector = LookingDown();
  calibration.projector_rms_px = 0.3;
  calibration.predicted_error = PredictedErrorRecord{};
  calibration.predicted_error->rms_mm = 0.25;
  service.SetCalibration(calibration, std::set<NodeId>{2, 4});
  service.OnLine(report::Calibrated{1, "self", "", "", "", "", "", 3});
  service.OnLine(report::RenderPattern{1, "grid"});
  report::BlendShown blend;
  blend.id = 1;
  blend.neighbours = {2};
  service.OnLine(blend);
  service.OnLine(report::CalibrationFailed{1, "no plane"});
  const wire::UnitStatus s = service.Snapshot();
  EXPECT_EQ(s.footprint_m_size(), 4 * kFootprintPointsPerEdge);
  EXPECT_DOUBLE_EQ(s.predicted_rms_mm(), 0.25);
  EXPECT_DOUBLE_EQ(s.projector_rms_px(), 0.3);
  EXPECT_EQ(s.round(), 3u);
  EXPECT_EQ(s.pattern(), "grid");
  EXPECT_TRUE(s.blended());
  ASSERT_EQ(s.neighbours_size(), 1);  // the blend's neighbours replace the round's
  EXPECT_EQ(s.neighbours(0), 2u);
  EXPECT_EQ(s.phase(), "failed");
  EXPECT_EQ(s.last_error(), "calibration failed: no plane");
}

TEST(UnitStatusServiceTest, AProblemSaysWhyTheUnitCannotWork) {
  UnitStatusService service("host-a");
  service.SetProblem("no factory calibration", "no factory calibration (--factory): ...");
  const wire::UnitStatus s = service.Snapshot();
  EXPECT_EQ(s.phase(), "no factory calibration");
  EXPECT_EQ(s.last_error(), "no factory calibration (--factory): ...");
}

}  // namespace
}  // namespace sandtable::node
