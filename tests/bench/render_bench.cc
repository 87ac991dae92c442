// The renderer's frame time at a projector's resolution on the default scene, every pass on,
// against the floor measured in the same run (one full-screen textured pass at the same size).
//
//   build/tests/bench/sandtable_render_bench [--frames 300] [--width 1280 --height 800]
//                                            [--out render-bench.json]
//
// The scene: the sandtable preset (seed 1) with synthetic aerial imagery draped over it from
// above (a 1024 x 1024 texture), seen by sandtable-3's unit 0 projector at its true pose (the
// default projector's Brown distortion, 3 px at most: the pre-warp runs). Every frame: the virtual
// sun moves (a new shadow map), 12 strokes, 4 personnel traces that grow and their heads, and the
// wand cursor (the overlay rebuilt), a blend mask. Reports frame time p50 / p99 (GL work
// finished), the per-pass times of a second run that finishes after each pass, the floor, and the
// context's description (llvmpipe, or a GPU's driver), for the shipped (deferred) renderer and
// for the forward passes with a separate warp pass and folded; and a re-blend's frame: a new mask
// over the last frame, set (`rewarp_ms_p50`) or prepared ahead (`prepared_rewarp_ms_*`; with
// --idle-s, also after the GPU sat idle). With --window (a display: xvfb-run), the frame to a
// GLFW window both ways a node can take: drawn headless, read back and shown (uploaded and drawn
// again by the window), or drawn straight into the window's back buffer and swapped
// (`window`). docs/render.md.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <random>
#include <thread>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#include <nlohmann/json.hpp>

#include "common/cli/command_line.h"
#include "common/scene/procedural_scene.h"
#include "node/devices/window_projector_output.h"
#include "node/render/gl_context.h"
#include "node/render/renderer.h"
#include "sim/site/site_presets.h"

namespace {

using namespace sandtable;
using namespace sandtable::node;

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t i = std::min(v.size() - 1, static_cast<size_t>(std::ceil(p * v.size()) - 1));
  return v[i];
}

// Fields and roads: smooth colour noise with a grid of darker lines, sRGB.
Texture AerialImagery(int side_px) {
  Texture t;
  t.width_px = t.height_px = side_px;
  t.rgba.resize(static_cast<size_t>(side_px) * side_px * 4);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> phase(0, 2 * M_PI);
  const double a = phase(rng), b = phase(rng), c = phase(rng);
  for (int y = 0; y < side_px; ++y) {
    for (int x = 0; x < side_px; ++x) {
      const double u = static_cast<double>(x) / side_px, v = static_cast<double>(y) / side_px;
      const double field = 0.5 + 0.25 * std::sin(13 * u + a) * std::cos(11 * v + b) +
                           0.15 * std::sin(37 * (u + v) + c);
      const bool road = (x % 128) < 5 || (y % 160) < 5;
      uint8_t* p = &t.rgba[(static_cast<size_t>(y) * side_px + x) * 4];
      p[0] = static_cast<uint8_t>(road ? 90 : 60 + 80 * field);
      p[1] = static_cast<uint8_t>(road ? 90 : 90 + 100 * field);
      p[2] = static_cast<uint8_t>(road ? 95 : 40 + 40 * field);
      p[3] = 255;
    }
  }
  return t;
}

Scene BenchScene() {
  ProceduralSceneOptions options;
  options.seed = 1;
  Scene scene = MakeProceduralScene(options)->scene;
  scene.textures.push_back(AerialImagery(1024));
  for (Material& m : scene.materials) m.base_color_texture = 0;
  const Eigen::AlignedBox3d box = scene.Bounds();
  scene.texcoords.clear();
  for (const Eigen::Vector3f& p : scene.positions_in_table_m) {
    scene.texcoords.emplace_back(static_cast<float>((p.x() - box.min().x()) / box.sizes().x()),
                                 static_cast<float>((box.max().y() - p.y()) / box.sizes().y()));
  }
  return scene;
}

RenderContent Content(int frame, const Eigen::AlignedBox3d& box) {
  RenderContent c;
  c.sun_direction_in_table = SunDirection(8.0 + 0.01 * frame);
  const double r = 0.45 * box.sizes().x();
  for (int s = 0; s < 12; ++s) {
    Polyline line;
    line.colour = Eigen::Vector3f(1.0f, 0.2f + 0.05f * s, 0.1f);
    line.width_m = 0.008;
    for (int k = 0; k < 40; ++k) {
      const double t = 0.02 * k + 0.5 * s;
      line.points_in_table_m.emplace_back(r * std::cos(t) * (0.3 + 0.05 * s),
                                          r * std::sin(t) * (0.3 + 0.05 * s), 0.0);
    }
    c.strokes.push_back(line);
  }
  for (int k = 0; k < 4; ++k) {
    Polyline trace;
    trace.colour = Eigen::Vector3f(0.1f, 0.4f + 0.15f * k, 1.0f);
    trace.width_m = 0.006;
    const int n = 50 + frame % 200;
    for (int i = 0; i < n; ++i) {
      const double t = 0.01 * i + k;
      trace.points_in_table_m.emplace_back(0.5 * r * std::cos(3 * t + k), 0.5 * r * std::sin(2 * t),
                                           0.0);
    }
    Marker head;
    head.position_in_table_m = trace.points_in_table_m.back();
    head.colour = trace.colour;
    head.radius_m = 0.02;
    c.traces.push_back(trace);
    c.markers.push_back(head);
  }
  Marker cursor;
  cursor.position_in_table_m = Eigen::Vector3d(0.1 * std::cos(0.05 * frame), 0.1, 0.0);
  cursor.ring = true;
  c.markers.push_back(cursor);
  c.overlay_version = static_cast<uint64_t>(frame) + 1;
  return c;
}

// The frame to a window of the view's size, `frames` each way with the shipped renderer, no
// vsync (the work, not the display's rate). "read_back" (how a node showed a window's frames
// before): drawn in a headless context and read back, then given to the window's Show() (an
// upload and a full-screen draw). GLX refuses the window's context on a thread that holds an
// EGL context (BadAccess), so the two halves run on two threads here, one after the other, and
// the frame's time is the sum of their medians. "direct": drawn into the window's back buffer
// and swapped, timed from the start of Render to the swap done.
Expected<nlohmann::json> TimeWindowPaths(const Scene& scene, const ProjectorView& view,
                                         const cv::Mat& mask, int frames) {
  WindowOptions options;
  options.windowed = true;
  options.windowed_size_px = cv::Size(view.projector.width_px, view.projector.height_px);
  options.vsync = false;
  Expected<std::unique_ptr<WindowProjectorOutput>> window = WindowProjectorOutput::Open(options);
  if (!window.ok()) return window.status();
  if ((*window)->size() != options.windowed_size_px) {
    return UnavailableError("the window is smaller than asked (the screen is too small)");
  }
  const auto ms = [](auto a, auto b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  auto make_renderer = [&](GlContext* context) -> Expected<std::unique_ptr<Renderer>> {
    Expected<std::unique_ptr<Renderer>> renderer = Renderer::Create(context, scene, {});
    if (!renderer.ok()) return renderer.status();
    ST_RETURN_IF_ERROR((*renderer)->SetView(view));
    ST_RETURN_IF_ERROR((*renderer)->SetMask(mask));
    return renderer;
  };
  nlohmann::json out;
  Status status = OkStatus();
  // Read back: the render thread's half, keeping a few distinct frames for the show's half.
  std::vector<double> render_ms, read_ms, show_ms;
  std::vector<cv::Mat> kept;
  std::string headless_context;
  std::thread([&] {
    Expected<std::unique_ptr<GlContext>> headless = CreateEglContext(options.windowed_size_px);
    if (!headless.ok()) {
      status = headless.status();
      return;
    }
    headless_context = (*headless)->description();
    Expected<std::unique_ptr<Renderer>> renderer = make_renderer(headless->get());
    if (!renderer.ok()) {
      status = renderer.status();
      return;
    }
    for (int f = -10; f < frames && status.ok(); ++f) {
      const auto t0 = std::chrono::steady_clock::now();
      Expected<FrameStats> stats = (*renderer)->Render(Content(f + 10, scene.Bounds()));
      const auto t1 = std::chrono::steady_clock::now();
      Expected<cv::Mat> frame =
          stats.ok() ? (*headless)->ReadOutput() : Expected<cv::Mat>(stats.status());
      const auto t2 = std::chrono::steady_clock::now();
      if (!frame.ok()) status = frame.status();
      if (f < 0 || !status.ok()) continue;
      render_ms.push_back(ms(t0, t1));
      read_ms.push_back(ms(t1, t2));
      if (kept.size() < 8) kept.push_back(*frame);
    }
  }).join();
  if (!status.ok()) return status.WithContext("read back");
  // ... and the show's: every frame a different picture, as a playing show's.
  for (int f = 0; f < frames; ++f) {
    const auto t0 = std::chrono::steady_clock::now();
    Expected<ShownFrame> shown = (*window)->Show(kept[f % kept.size()]);
    if (!shown.ok()) return shown.status().WithContext("read back: show");
    show_ms.push_back(ms(t0, std::chrono::steady_clock::now()));
  }
  nlohmann::json& read_back = out["read_back"];
  read_back["render_ms_p50"] = Percentile(render_ms, 0.5);
  read_back["read_back_ms_p50"] = Percentile(read_ms, 0.5);
  read_back["show_ms_p50"] = Percentile(show_ms, 0.5);
  read_back["frame_to_window_ms_p50"] =
      Percentile(render_ms, 0.5) + Percentile(read_ms, 0.5) + Percentile(show_ms, 0.5);
  read_back["context"] = headless_context;
  // Direct, on a thread of its own as the node's render thread.
  std::thread([&] {
    std::unique_ptr<GlContext> in_window;
    WindowProjectorOutput::ContextHold hold(window->get());
    in_window = CreateWindowContext(window->get());
    Expected<std::unique_ptr<Renderer>> renderer = make_renderer(in_window.get());
    if (!renderer.ok()) {
      status = renderer.status();
      return;
    }
    std::vector<double> total_ms, draw_ms, swap_ms;
    for (int f = -10; f < frames; ++f) {
      const auto t0 = std::chrono::steady_clock::now();
      Expected<FrameStats> stats = (*renderer)->Render(Content(f + 10, scene.Bounds()));
      const auto t1 = std::chrono::steady_clock::now();
      Expected<ShownFrame> shown =
          stats.ok() ? in_window->Present() : Expected<ShownFrame>(stats.status());
      const auto t2 = std::chrono::steady_clock::now();
      if (!shown.ok()) {
        status = shown.status();
        return;
      }
      if (f < 0) continue;
      total_ms.push_back(ms(t0, t2));
      draw_ms.push_back(ms(t0, t1));
      swap_ms.push_back(ms(t1, t2));
    }
    nlohmann::json& direct = out["direct"];
    direct["render_ms_p50"] = Percentile(draw_ms, 0.5);
    direct["swap_ms_p50"] = Percentile(swap_ms, 0.5);
    direct["frame_to_window_ms_p50"] = Percentile(total_ms, 0.5);
    direct["frame_to_window_ms_p99"] = Percentile(total_ms, 0.99);
    direct["context"] = in_window->description();
    renderer->reset();  // while the hold keeps the context current
  }).join();
  if (!status.ok()) return status.WithContext("direct");
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app("The renderer's frame time against the floor (docs/render.md)",
               "sandtable_render_bench");
  cli::Configure(app);
  int frames = 300, width = 1280, height = 800;
  std::string out;
  app.add_option("--frames", frames, "frames per run")->check(cli::Integer(10, 100000));
  app.add_option("--width", width, "output width, px")->check(cli::Integer(16, 8192));
  app.add_option("--height", height, "output height, px")->check(cli::Integer(16, 8192));
  app.add_option("--out", out, "JSON file of the figures");
  double idle_s = 0.0;
  app.add_option("--idle-s", idle_s,
                 "also time three prepared re-blend frames after this many seconds idle each");
  bool window = false;
  app.add_flag("--window", window,
               "also time frames to a GLFW window (needs a display, e.g. xvfb-run -s "
               "'-screen 0 1920x1080x24'): read back and shown, against drawn into it");
  if (std::optional<int> exit = cli::Parse(app, argc, argv)) return *exit;

  Expected<sim::Site> site = sim::MakeSitePreset("sandtable-3");
  if (!site.ok()) return 1;
  const sim::UnitSpec& unit = site->units[0];
  CameraModel projector = unit.projector.model;
  const double scale = static_cast<double>(width) / projector.width_px;
  projector.fx_px *= scale;
  projector.fy_px *= static_cast<double>(height) / projector.height_px;
  projector.cx_px = (projector.cx_px + 0.5) * scale - 0.5;
  projector.cy_px = (projector.cy_px + 0.5) * height / projector.height_px - 0.5;
  projector.width_px = width;
  projector.height_px = height;

  const Scene scene = BenchScene();
  Expected<ProjectorView> view = PrepareProjectorView(
      projector, unit.projector.table_from_projector.Inverse(), scene.Bounds());
  if (!view.ok()) {
    std::cerr << view.status().ToString() << "\n";
    return 1;
  }
  cv::Mat mask(height, width, CV_32FC1);
  for (int u = 0; u < width; ++u) mask.col(u).setTo(std::min(1.0, 0.5 + u / (1.0 * width)));
  // The window first: this thread must hold no EGL context when it shows (GLX refuses).
  nlohmann::json window_report;
  if (window) {
    Expected<nlohmann::json> timed = TimeWindowPaths(scene, *view, mask, frames);
    if (!timed.ok()) {
      std::cerr << timed.status().ToString() << "\n";
      return 1;
    }
    window_report = *timed;
  }
  Expected<std::unique_ptr<GlContext>> context = CreateEglContext(cv::Size(width, height));
  if (!context.ok()) {
    std::cerr << context.status().ToString() << "\n";
    return 1;
  }

  nlohmann::json report;
  report["context"] = (*context)->description();
  report["width_px"] = width;
  report["height_px"] = height;
  report["triangles"] = scene.NumTriangles();
  report["frames"] = frames;
  report["max_distortion_px"] = view->max_displacement_px;
  // The shipped renderer (deferred: the surface cache drawn once, then the light pass and the
  // overlay each frame), then the same frames drawn whole every frame with the pre-warp and mask
  // as a separate full-screen pass, and with them folded into the scene pass (the measurements
  // behind the default).
  enum class Config { kDeferred, kSeparateWarpPass, kFolded };
  for (const Config config : {Config::kDeferred, Config::kSeparateWarpPass, Config::kFolded}) {
    const bool fold = config == Config::kFolded;
    std::vector<double> frame_ms;
    std::vector<std::vector<double>> pass_ms(kPassCount);
    nlohmann::json& run = report[config == Config::kDeferred           ? "deferred"
                                 : config == Config::kSeparateWarpPass ? "separate_warp_pass"
                                                                       : "folded"];
    for (bool timed_passes : {false, true}) {
      RendererOptions options;
      options.time_passes = timed_passes;
      options.fold_prewarp = fold;
      options.deferred = config == Config::kDeferred;
      Expected<std::unique_ptr<Renderer>> renderer =
          Renderer::Create(context->get(), scene, options);
      if (!renderer.ok() || !(*renderer)->SetView(*view).ok() || !(*renderer)->SetMask(mask).ok()) {
        std::cerr << "renderer: " << renderer.status().ToString() << "\n";
        return 1;
      }
      for (int f = -10; f < frames; ++f) {  // 10 frames of warm-up
        Expected<FrameStats> stats = (*renderer)->Render(Content(f + 10, scene.Bounds()));
        if (!stats.ok()) {
          std::cerr << stats.status().ToString() << "\n";
          return 1;
        }
        // The first frame of a view: the deferred renderer draws its surface cache.
        if (f == -10 && !timed_passes) run["first_frame_ms"] = stats->frame_ms;
        if (f < 0) continue;
        run["scene_triangles_drawn"] = stats->scene_triangles;
        run["overlay_triangles"] = stats->overlay_triangles;
        run["tessellation_px"] = stats->tessellation_px;
        if (!timed_passes) {
          frame_ms.push_back(stats->frame_ms);
        } else {
          for (int p = 0; p < kPassCount; ++p) {
            if (stats->ran[p]) pass_ms[p].push_back(stats->pass_ms[p]);
          }
        }
      }
      if (!timed_passes && config != Config::kFolded) {
        // A new mask over the last frame (a re-blend's first frame): Renderer::Rewarp.
        std::vector<double> rewarp_ms;
        for (int f = 0; f < std::min(frames, 100); ++f) {
          if (!(*renderer)->SetMask(mask).ok()) return 1;
          Expected<FrameStats> stats = (*renderer)->Rewarp();
          if (!stats.ok()) {
            std::cerr << stats.status().ToString() << "\n";
            return 1;
          }
          rewarp_ms.push_back(stats->frame_ms);
        }
        run["rewarp_ms_p50"] = Percentile(rewarp_ms, 0.5);
        // A mask prepared ahead (as a node prepares one per neighbour that may leave), a few
        // frames drawn meanwhile, then made current and shown over the last frame: the re-blend
        // after a kill. Timed from UseMask to the rewarped frame finished.
        // UseMask(key) and the rewarped frame, finished: ms, or -1 (the error printed).
        auto show_prepared_ms = [&](uint64_t key) {
          const auto t0 = std::chrono::steady_clock::now();
          const Status used = (*renderer)->UseMask(key);
          Expected<FrameStats> stats = used.ok() ? (*renderer)->Rewarp() : used;
          if (!stats.ok()) {
            std::cerr << stats.status().ToString() << "\n";
            return -1.0;
          }
          return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
              .count();
        };
        std::vector<double> prepared_ms;
        for (int f = 0; f < std::min(frames, 30); ++f) {
          if (!(*renderer)->PrepareMask(f + 1, mask).ok()) return 1;
          for (int k = 0; k < 3; ++k) {
            if (!(*renderer)->Render(Content(frames + 3 * f + k, scene.Bounds())).ok()) return 1;
          }
          prepared_ms.push_back(show_prepared_ms(f + 1));
          if (prepared_ms.back() < 0) return 1;
        }
        // The same after the GPU sat idle (--idle-s): a site whose timeline is paused draws only
        // on change, so the re-blend after a kill may come seconds after the last frame.
        if (idle_s > 0 && config == Config::kDeferred) {
          std::vector<double> idle_ms;
          for (int f = 0; f < 3; ++f) {
            if (!(*renderer)->PrepareMask(1000 + f, mask).ok()) return 1;
            if (!(*renderer)->Render(Content(frames + f, scene.Bounds())).ok()) return 1;
            std::this_thread::sleep_for(std::chrono::duration<double>(idle_s));
            idle_ms.push_back(show_prepared_ms(1000 + f));
            if (idle_ms.back() < 0) return 1;
          }
          run["prepared_rewarp_after_idle_ms"] = idle_ms;
          run["idle_s"] = idle_s;
        }
        run["prepared_rewarp_ms_first"] = prepared_ms.front();
        run["prepared_rewarp_ms_p50"] = Percentile(prepared_ms, 0.5);
        run["prepared_rewarp_ms_max"] = *std::max_element(prepared_ms.begin(), prepared_ms.end());
      }
      if (!timed_passes && config == Config::kDeferred) {
        std::vector<double> floor_ms;
        for (int f = 0; f < frames; ++f) {
          Expected<double> ms = (*renderer)->RenderFloor();
          if (ms.ok()) floor_ms.push_back(*ms);
        }
        report["floor_ms_p50"] = Percentile(floor_ms, 0.5);
        report["floor_ms_p99"] = Percentile(floor_ms, 0.99);
      }
    }
    run["frame_ms_p50"] = Percentile(frame_ms, 0.5);
    run["frame_ms_p99"] = Percentile(frame_ms, 0.99);
    run["frame_over_floor"] =
        run["frame_ms_p50"].get<double>() / std::max(1e-9, report["floor_ms_p50"].get<double>());
    for (int p = 0; p < kPassCount; ++p) {
      const char* name = PassName(static_cast<Pass>(p));
      run["pass_ms_p50"][name] = Percentile(pass_ms[p], 0.5);
      run["pass_frames"][name] = pass_ms[p].size();
    }
  }
  // What a re-blend adds before its first frame (a new mask swapped in) and what every frame
  // costs after the passes (the read back of the output for the projector).
  {
    Expected<std::unique_ptr<Renderer>> renderer =
        Renderer::Create(context->get(), scene, RendererOptions{});
    if (!renderer.ok() || !(*renderer)->SetView(*view).ok()) return 1;
    std::vector<double> set_mask_ms, read_ms;
    for (int i = 0; i < 30; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      if (!(*renderer)->SetMask(mask).ok()) return 1;
      glFinish();
      const auto t1 = std::chrono::steady_clock::now();
      if (!(*context)->ReadOutput().ok()) return 1;
      const auto t2 = std::chrono::steady_clock::now();
      set_mask_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      read_ms.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
    }
    report["set_mask_ms_p50"] = Percentile(set_mask_ms, 0.5);
    report["read_output_ms_p50"] = Percentile(read_ms, 0.5);
  }
  if (window) report["window"] = window_report;
  report["frame_ms_p50"] = report["deferred"]["frame_ms_p50"];
  report["frame_ms_p99"] = report["deferred"]["frame_ms_p99"];
  report["frame_over_floor"] = report["deferred"]["frame_over_floor"];
  std::cout << report.dump(2) << "\n";
  if (!out.empty()) {
    std::ofstream file(out);
    file << report.dump(2) << "\n";
    if (!file) {
      std::cerr << "cannot write " << out << "\n";
      return 1;
    }
  }
  return 0;
}
