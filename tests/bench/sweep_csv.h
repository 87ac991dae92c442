// A minimal CSV writer for the numerics sweeps, and helpers every sweep uses.
// Non-finite values are written as "nan" (gnuplot skips them); the last column of every sweep
// is `status`: "ok" or the StatusCode name of the error the routine returned ("DEGENERATE").
#pragma once

#include <chrono>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <string>
#include <variant>

#include "common/base/status.h"

namespace sandtable::bench {

class CsvWriter {
 public:
  using Cell = std::variant<double, long long, std::string>;
  // Opens dir/name and writes the header; ST_CHECKs that the file opened.
  CsvWriter(const std::string& dir, const std::string& name,
            std::initializer_list<std::string> columns);
  void Row(std::initializer_list<Cell> cells);
  int rows() const { return rows_; }

 private:
  std::ofstream out_;
  size_t num_columns_ = 0;
  int rows_ = 0;
};

inline std::string StatusCell(const Status& status) {
  return status.ok() ? std::string("ok") : std::string(StatusCodeName(status.code()));
}

// Wall time of a callable in ms.
template <typename F>
double TimeMs(F&& f) {
  const auto start = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

// Each sweep writes one CSV into `dir`; `quick` shrinks it (fewer seeds and sizes) for smoke
// runs. Declared here, defined in sweeps_estimation.cc and sweeps_geometry.cc.
void SweepRuntimeVsError(const std::string& dir, bool quick);
void SweepCoordinateScale(const std::string& dir, bool quick);
void SweepNearCoplanar(const std::string& dir, bool quick);
void SweepGrazing(const std::string& dir, bool quick);
void SweepRansacOutliers(const std::string& dir, bool quick);
void SweepUndistortion(const std::string& dir, bool quick);
void SweepGlFloat(const std::string& dir, bool quick);
void SweepTriangulation(const std::string& dir, bool quick);
void SweepPlaneFitNoise(const std::string& dir, bool quick);
void SweepUmeyama(const std::string& dir, bool quick);
void SweepTableFrame(const std::string& dir, bool quick);

}  // namespace sandtable::bench
