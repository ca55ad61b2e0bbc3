// A program using the installed octocut: loads a scene, steps its World and cuts once with its first tool.
// usage: consumer SCENE STEPS; exit 0 when the steps ran and the cut removed material.
#include <cstdio>
#include <cstdlib>
#include <exception>

#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/version.hpp"

int main(int argc, char** argv) {
  using namespace octocut;
  if (argc != 3) {
    std::fprintf(stderr, "usage: consumer SCENE STEPS\n");
    return 2;
  }
  try {
    engine::World world(engine::load_scene(argv[1]), engine::WorldOptions{.render = false});
    for (long i = 0; i < std::atol(argv[2]) && !world.done(); ++i) world.step();
    const engine::CutSummary cut = world.cut_now(0);
    const engine::Report report = world.report();
    std::printf("octocut %s: t = %g s, %ld steps; cut by %s: %s, %g m^3 removed; %ld elements\n", kVersion,
                world.time(), report.steps, cut.tool.c_str(), cut.status.c_str(), cut.removed_volume_m3,
                report.elements);
    return cut.status == "ok" && cut.removed_volume_m3 > 0.0 && report.finite ? 0 : 1;
  } catch (const std::exception& e) {  // engine::SceneError: bad input
    std::fprintf(stderr, "consumer: %s\n", e.what());
    return 1;
  }
}
