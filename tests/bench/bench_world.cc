// Simulated world on one core: the transport map of a 1024x768 camera with 3 projectors on the
// default sand-table scene, and one capture synthesis. Run pinned to one core:
//   taskset -c 0 build/tests/bench/bench_world
#include <benchmark/benchmark.h>

#include "common/scene/procedural_scene.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"

namespace sandtable::sim {
namespace {

std::unique_ptr<World> MakeDefaultWorld() {
  Site site = *MakeSitePreset("sandtable-3");
  ProceduralSceneOptions options;
  options.seed = 1;
  WorldOptions world_options;
  world_options.transport.num_threads = 1;
  world_options.embree_config = "threads=1";
  Expected<std::unique_ptr<World>> world =
      World::Create(site, MakeProceduralScene(options)->scene, world_options);
  ST_CHECK(world.ok()) << world.status().ToString();
  return std::move(*world);
}

void BM_TransportMap1024x768ThreeProjectors(benchmark::State& state) {
  const std::unique_ptr<World> world = MakeDefaultWorld();
  const UnitSpec& unit = world->site().units[0];
  const View view = View::Perspective(unit.camera->model, world->site().TableFromCamera(unit));
  TransportOptions options;
  options.num_threads = 1;
  size_t entries = 0;
  for (auto _ : state) {
    Expected<TransportMap> map = BuildTransportMap(world->site(), world->caster(), view, options);
    entries = map->NumEntries();
    benchmark::DoNotOptimize(map);
  }
  state.counters["entries"] = static_cast<double>(entries);
  state.counters["triangles"] = world->scene().NumTriangles();
}
BENCHMARK(BM_TransportMap1024x768ThreeProjectors)->Unit(benchmark::kMillisecond)->Iterations(3);

void BM_Capture(benchmark::State& state) {
  const std::unique_ptr<World> world = MakeDefaultWorld();
  for (NodeId id : {0u, 1u, 2u}) ST_CHECK(world->SetProjectorUniform(id, 200).ok());
  ST_CHECK(world->CameraTransport(0).ok());
  uint64_t seed = 0;
  const bool noise = state.range(0) != 0;
  for (auto _ : state) {
    Expected<cv::Mat> image = world->Capture(0, {.enabled = noise, .seed = seed++});
    benchmark::DoNotOptimize(image);
  }
}
BENCHMARK(BM_Capture)->Arg(1)->Arg(0)->ArgNames({"noise"})->Unit(benchmark::kMillisecond);

void BM_SetProjectorFrame1280x800(benchmark::State& state) {
  const std::unique_ptr<World> world = MakeDefaultWorld();
  cv::Mat frame(800, 1280, CV_8UC1);
  cv::randu(frame, 0, 256);
  for (auto _ : state) ST_CHECK(world->SetProjectorFrame(0, frame).ok());
}
BENCHMARK(BM_SetProjectorFrame1280x800)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace sandtable::sim

BENCHMARK_MAIN();
