// libFuzzer target over the calibration file formats, from bytes. The first byte picks the
// format, the rest is the file's text:
//   0: unit calibration, versions 1 and 2 (common/io/unit_calibration_file.h), which is also the
//      factory file the world writes (sim/site/factory_calibration.h)
//   1: true pose (node/app/calibration_service.h, the lab's test mode)
//   2: OpenCV YAML export read back (common/io/opencv_yaml.h)
// Invariants: a unit calibration that parses re-serialises and parses again; nothing throws.
// Seeds in tests/fuzz/json_formats_corpus/ (one file per format and version); see deploy/fuzz.sh.
#include <cstdint>
#include <string>
#include <string_view>

#include "common/base/check.h"
#include "common/io/opencv_yaml.h"
#include "common/io/unit_calibration_file.h"
#include "node/app/calibration_service.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace sandtable;
  if (size < 1 || size > (1u << 20)) return 0;  // the files are a few kB
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  switch (data[0] % 3) {
    case 0: {
      Expected<UnitCalibration> c = ParseUnitCalibration(text, "fuzz.unit.json");
      if (!c.ok()) return 0;
      // What Save writes must Load: only calibrations that pass Check are ever saved.
      if (!c->Check().ok()) return 0;
      Expected<UnitCalibration> again =
          ParseUnitCalibration(UnitCalibrationToJson(*c), "fuzz.unit.json (again)");
      ST_CHECK(again.ok()) << "a parsed unit calibration must re-parse: "
                           << again.status().ToString();
      ST_CHECK(again->unit_id == c->unit_id);
      return 0;
    }
    case 1:
      (void)node::ParseTruePose(text, "fuzz.true_pose.json");
      return 0;
    default:
      (void)ParseOpenCvYaml(text, "fuzz.yaml");
      return 0;
  }
}
