// Every lab options struct: the defaults (with the flags a command requires) check, and each
// bad value is refused naming what is wrong.
#include <atomic>
#include <chrono>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "sim/lab/lab_chaos.h"
#include "sim/lab/lab_painter.h"
#include "sim/lab/lab_run.h"
#include "sim/lab/lab_scale.h"
#include "sim/lab/lab_sweep.h"

namespace sandtable::sim {
namespace {

template <typename Options>
void ExpectChecks(const Options& good,
                  const std::vector<std::pair<std::function<void(Options&)>, std::string>>& bad) {
  EXPECT_TRUE(good.Check().ok()) << good.Check().ToString();
  for (const auto& [spoil, says] : bad) {
    Options o = good;
    spoil(o);
    const Status checked = o.Check();
    EXPECT_EQ(checked.code(), StatusCode::kInvalidArgument) << says;
    EXPECT_NE(checked.message().find(says), std::string::npos) << checked.message();
  }
}

TEST(LabOptionsTest, ScaleSweepChaosAndPainterCheckTheirValues) {
  LabScaleOptions scale;
  scale.out_dir = "out";
  ExpectChecks<LabScaleOptions>(
      scale, {{[](auto& o) { o.out_dir.clear(); }, "--out"},
              {[](auto& o) { o.nodes.clear(); }, "--nodes"},
              {[](auto& o) {
                 o.nodes = {2, 65};
               },
               "65"},
              {[](auto& o) { o.metric_samples = 0; }, "--samples"},
              {[](auto& o) { o.resolution_scale = 0.0; }, "--resolution-scale"}});
  LabSweepOptions sweep;
  sweep.out_dir = "out";
  ExpectChecks<LabSweepOptions>(sweep, {{[](auto& o) { o.out_dir.clear(); }, "--out"},
                                        {[](auto& o) { o.metric_samples = -1; }, "--samples"}});
  LabChaosOptions chaos;
  chaos.out_dir = "out";
  ExpectChecks<LabChaosOptions>(chaos, {{[](auto& o) { o.out_dir.clear(); }, "--out"},
                                        {[](auto& o) { o.runs = 0; }, "--runs"},
                                        {[](auto& o) { o.runs = 1001; }, "--runs"},
                                        {[](auto& o) { o.metric_samples = 0; }, "--samples"}});
  LabPainterOptions painter;
  painter.requests_endpoint = "tcp://127.0.0.1:5555";
  ExpectChecks<LabPainterOptions>(
      painter, {{[](auto& o) { o.requests_endpoint.clear(); }, "endpoint"},
                {[](auto& o) { o.points_per_s = 0.0; }, "points_per_s"},
                {[](auto& o) { o.window = 0; }, "window"},
                {[](auto& o) { o.ack_timeout = std::chrono::milliseconds(0); }, "ack_timeout"}});
}

TEST(LabOptionsTest, ACommandWithBadOptionsSaysSoAndExitsWithUsage) {
  std::atomic<bool> stop{false};
  std::ostringstream out, err;
  LabChaosOptions chaos;  // no --out
  EXPECT_EQ(RunChaos(chaos, stop, out, err), 2);
  EXPECT_NE(err.str().find("--out"), std::string::npos) << err.str();
  LabScaleOptions scale;
  scale.out_dir = "out";
  scale.nodes = {0};
  err.str("");
  EXPECT_EQ(RunScale(scale, stop, out, err), 2);
  EXPECT_NE(err.str().find("--nodes"), std::string::npos) << err.str();
}

}  // namespace
}  // namespace sandtable::sim
