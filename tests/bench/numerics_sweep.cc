// sandtable_numerics_sweep --out DIR [--quick] [--only NAME]
// Writes the CSV files of docs/numerics.md into DIR: run time against error, and breakdown
// sweeps (noise, coordinate scale, near-coplanar points, grazing views, RANSAC outliers,
// undistortion, GL float vs double, triangulation angle, plane fit, Umeyama, table frame).
// tests/bench/plot_sweeps.sh DIR turns them into PNGs. Single-threaded, deterministic seeds.
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <cmath>

#include "common/cli/command_line.h"
#include "tests/bench/sweep_csv.h"

namespace sandtable::bench {

CsvWriter::CsvWriter(const std::string& dir, const std::string& name,
                     std::initializer_list<std::string> columns)
    : out_(std::filesystem::path(dir) / name), num_columns_(columns.size()) {
  ST_CHECK(out_.good()) << "cannot write " << dir << "/" << name;
  bool first = true;
  for (const std::string& c : columns) {
    out_ << (first ? "" : ",") << c;
    first = false;
  }
  out_ << "\n";
}

void CsvWriter::Row(std::initializer_list<Cell> cells) {
  ST_CHECK(cells.size() == num_columns_)
      << "CSV row has " << cells.size() << " cells, header " << num_columns_;
  bool first = true;
  char buffer[64];
  for (const Cell& cell : cells) {
    if (!first) out_ << ",";
    first = false;
    if (const double* d = std::get_if<double>(&cell)) {
      if (std::isfinite(*d)) {
        std::snprintf(buffer, sizeof(buffer), "%.6g", *d);
        out_ << buffer;
      } else {
        out_ << "nan";
      }
    } else if (const long long* i = std::get_if<long long>(&cell)) {
      out_ << *i;
    } else {
      out_ << std::get<std::string>(cell);
    }
  }
  out_ << "\n";
  ++rows_;
}

}  // namespace sandtable::bench

int main(int argc, char** argv) {
  using namespace sandtable::bench;
  const std::vector<std::pair<std::string, std::function<void(const std::string&, bool)>>> sweeps =
      {
          {"runtime_vs_error", SweepRuntimeVsError},
          {"coordinate_scale", SweepCoordinateScale},
          {"near_coplanar", SweepNearCoplanar},
          {"grazing", SweepGrazing},
          {"ransac_outliers", SweepRansacOutliers},
          {"undistortion", SweepUndistortion},
          {"gl_float", SweepGlFloat},
          {"triangulation", SweepTriangulation},
          {"plane_fit_noise", SweepPlaneFitNoise},
          {"umeyama", SweepUmeyama},
          {"table_frame", SweepTableFrame},
      };
  std::vector<std::string> names;
  for (const auto& sweep : sweeps) names.push_back(sweep.first);
  std::string out_dir, only;
  bool quick = false;
  CLI::App app("The geometry core's sweeps: run time against error and breakdown curves (CSV).",
               "sandtable_numerics_sweep");
  sandtable::cli::Configure(app);
  app.add_option("--out", out_dir, "folder of the CSV files")->required();
  app.add_flag("--quick", quick, "fewer trials (a smoke run)");
  app.add_option("--only", only, "run only this sweep")->check(CLI::IsMember(names));
  if (std::optional<int> exit = sandtable::cli::Parse(app, argc, argv)) return *exit;
  std::error_code error;
  std::filesystem::create_directories(out_dir, error);
  if (error) {
    std::fprintf(stderr, "cannot create %s: %s\n", out_dir.c_str(), error.message().c_str());
    return 1;
  }
  double total_ms = 0.0;
  for (const auto& [name, sweep] : sweeps) {
    if (!only.empty() && only != name) continue;
    const double ms = TimeMs([&] { sweep(out_dir, quick); });
    total_ms += ms;
    std::printf("%-18s %8.1f s  -> %s/%s.csv\n", name.c_str(), ms / 1000.0, out_dir.c_str(),
                name.c_str());
    std::fflush(stdout);
  }
  std::printf("total %.1f s\n", total_ms / 1000.0);
  return 0;
}
