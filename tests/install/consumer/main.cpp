// A program using the installed octocut: loads a scene, runs its timeline (steps and cuts), prints the cuts.
// usage: consumer SCENE OUT_DIR; exit 0 when the run succeeded with at least one cut of status ok.
#include <cstdio>
#include <exception>

#include "octocut/engine/scene_loader.hpp"
#include "octocut/engine/world.hpp"
#include "octocut/version.hpp"

int main(int argc, char** argv) {
  using namespace octocut;
  if (argc != 3) {
    std::fprintf(stderr, "usage: consumer SCENE OUT_DIR\n");
    return 2;
  }
  engine::RunResult r;
  try {
    engine::RunOptions options;
    options.out_dir = argv[2];
    options.no_render = true;
    r = engine::run_scene(engine::load_scene(argv[1]), options);
  } catch (const std::exception& e) {  // engine::SceneError: bad input
    std::fprintf(stderr, "consumer: %s\n", e.what());
    return 1;
  }
  int ok = 0;
  for (const engine::CutSummary& c : r.cuts) {
    std::printf("cut at t = %g s by %s: %s %s\n", c.t, c.tool.c_str(), c.status.c_str(), c.reason.c_str());
    ok += c.status == "ok";
  }
  std::printf("octocut %s: exit code %d %s, %d ok cuts, report %s\n", kVersion, r.exit_code, r.error.c_str(), ok,
              r.report_path.c_str());
  return r.exit_code == 0 && ok > 0 ? 0 : 1;
}
