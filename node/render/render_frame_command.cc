#include "node/render/render_frame_command.h"

#include <iostream>

#include <opencv2/imgproc.hpp>

#include "cluster/personnel_tracks.h"
#include "common/cli/command_line.h"
#include "common/io/image_file.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/gltf_loader.h"
#include "node/render/gl_context.h"
#include "node/render/render_loop.h"
#include "node/render/renderer.h"
#include "node/render/show_content.h"

namespace sandtable::node {

int RunRenderFrame(const std::vector<std::string>& args) {
  std::string calibration_path, output_path, model_path, pattern_name = "none", timeline_path;
  std::string sun = "on";
  double media_s = 0.0;
  uint32_t id = 0;
  SunOptions sun_options;
  CLI::App app("One frame of a unit's show, written to a PNG (docs/render.md).",
               "sandtable-node render-frame");
  cli::Configure(app);
  app.add_option("--calibration", calibration_path, "the unit's site calibration (unit-N.json)")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("-o,--output", output_path, "the PNG to write")->required();
  app.add_option("--model", model_path, "the glTF model (placed with table_from_model)")
      ->check(CLI::ExistingFile);
  app.add_option("--pattern", pattern_name,
                 "none (the show), id, grid, white, raw-white, bars, black")
      ->check(CLI::IsMember({"none", "id", "grid", "white", "raw-white", "bars", "black"}));
  app.add_option("--timeline", timeline_path, "personnel tracks (CSV) drawn as traces")
      ->check(CLI::ExistingFile);
  app.add_option("--media-s", media_s, "the media time drawn, s")->check(cli::Real(0.0, 1e9));
  app.add_option("--sun", sun, "the virtual sun")->check(CLI::IsMember({"on", "off"}));
  app.add_option("--sun-start-h", sun_options.start_hour, "time of day at media time 0, h")
      ->check(cli::Real(0.0, 24.0));
  app.add_option("--sun-hours-per-s", sun_options.hours_per_media_s,
                 "hours of the day per media second")
      ->check(cli::Real(0.0, 3600.0));
  app.add_option("--id", id, "the unit id the id pattern shows");
  if (std::optional<int> exit = cli::Parse(app, args)) return *exit;
  auto usage = [&](const std::string& why) { return cli::UsageError(app, why); };

  Expected<UnitCalibration> calibration = LoadUnitCalibration(calibration_path);
  if (!calibration.ok()) return usage("--calibration: " + calibration.status().ToString());
  if (!calibration->table_from_projector) {
    return usage("--calibration: " + calibration_path +
                 " is not a site calibration (no table_from_projector)");
  }
  std::optional<Scene> model;
  if (!model_path.empty()) {
    Expected<Scene> loaded = LoadGltfScene(model_path);
    if (!loaded.ok()) return usage("--model: " + loaded.status().ToString());
    model = std::move(*loaded);
  }
  ShowInputs inputs;
  inputs.pattern = *TestPatternFromName(pattern_name);
  inputs.projector_id = id;
  inputs.sun = sun_options;
  inputs.sun.enabled = sun == "on";
  const Scene scene = RenderLoop::SceneFor(model ? &*model : nullptr, *calibration);
  if (!timeline_path.empty()) {
    Expected<cluster::PersonnelTracks> tracks = cluster::PersonnelTracks::Load(timeline_path);
    if (!tracks.ok()) return usage("--timeline: " + tracks.status().ToString());
    inputs.tracks = std::make_shared<const std::vector<DrapedTrack>>(DrapeTracks(*tracks, &scene));
  }
  const CameraModel& projector = calibration->projector;
  Expected<std::unique_ptr<GlContext>> context =
      CreateEglContext(cv::Size(projector.width_px, projector.height_px));
  Expected<std::unique_ptr<Renderer>> renderer =
      context.ok() ? Renderer::Create(context->get(), scene)
                   : Expected<std::unique_ptr<Renderer>>(context.status());
  Expected<ProjectorView> view =
      PrepareProjectorView(projector, calibration->table_from_projector->Inverse(), scene.Bounds());
  Status status = !renderer.ok() ? renderer.status() : !view.ok() ? view.status() : OkStatus();
  if (status.ok()) status = (*renderer)->SetView(*view);
  Expected<FrameStats> stats = status.ok() ? (*renderer)->Render(BuildContent(inputs, media_s))
                                           : Expected<FrameStats>(status);
  Expected<cv::Mat> frame =
      stats.ok() ? (*context)->ReadOutput() : Expected<cv::Mat>(stats.status());
  if (frame.ok()) {
    cv::Mat bgr;
    cv::cvtColor(*frame, bgr, cv::COLOR_RGB2BGR);
    status = io::WritePngFile(output_path, bgr);
  } else {
    status = frame.status();
  }
  if (!status.ok()) {
    std::cerr << "sandtable-node render-frame: " << status.ToString() << "\n";
    return cli::kExitFailure;
  }
  std::cout << "sandtable-node render-frame: " << output_path << " (" << projector.width_px << "x"
            << projector.height_px << ", " << stats->frame_ms << " ms, "
            << (*context)->description() << ")\n";
  return 0;
}

}  // namespace sandtable::node
