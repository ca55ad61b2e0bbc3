// Benchmark (label `bench`, not in CI): `octocut view` on meniscus_punch under Xvfb and Mesa llvmpipe for a fixed
// wall time with nobody touching it, against `octocut run --no-render` of the same scene without its cuts. Prints the
// viewer's frame rate and real-time factor, and checks that the simulation thread's median step time stays within
// 10 % of the headless run's (the window must not slow the simulation down). Figures in docs/RESULTS.md.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>

#include "common/cli_util.hpp"
#include "common/temp_dir.hpp"
#include "common/xvfb.hpp"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json read_json(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in);
}

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

class ViewBench : public octocut::test::TempDirTest {};

TEST_F(ViewBench, FrameRateRealTimeFactorAndStepTime) {
  const std::string scene = std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/meniscus_punch.json";
  const double seconds = std::getenv("OCTOCUT_VIEW_BENCH_S") ? std::atof(std::getenv("OCTOCUT_VIEW_BENCH_S")) : 20.0;
  octocut::test::Xvfb xvfb(m_dir / "xvfb.log");
  ASSERT_FALSE(xvfb.display().empty()) << read_text(m_dir / "xvfb.log");
  {
    octocut::test::Child viewer({OCTOCUT_EXE, "view", scene, "--out", (m_dir / "view").string()},
                                {"DISPLAY=" + xvfb.display()}, m_dir / "view.log");
    const std::string search = "DISPLAY=" + xvfb.display() + " timeout 20 xdotool search --sync --name octocut >/dev/null";
    ASSERT_EQ(std::system(search.c_str()), 0) << read_text(m_dir / "view.log");
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    const std::string esc = "DISPLAY=" + xvfb.display() + " timeout 10 xdotool search --name octocut key Escape";
    ASSERT_EQ(std::system(esc.c_str()), 0);
    ASSERT_EQ(viewer.wait_exit(std::chrono::seconds(30)), 0) << read_text(m_dir / "view.log");
  }
  const json view = read_json(m_dir / "view" / "report.json");
  const double wall = view["wall_time_s"].get<double>(), sim = view["sim_time_s"].get<double>();
  const double fps = view["frames"]["rendered"].get<double>() / wall;
  const double view_step = view["timing_ms"]["step"]["median"].get<double>();

  // The same scene headless for the same simulated time, without the timeline's cuts (the viewer holds the tool).
  const octocut::test::CommandResult r = octocut::test::run_octocut(
      "run '" + scene + "' --no-render --quiet --set '/tools/0/cuts=[]' --set /duration=" + std::to_string(sim) +
      " --out '" + (m_dir / "run").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const double run_step = read_json(m_dir / "run" / "report.json")["timing_ms"]["step"]["median"].get<double>();

  std::printf("viewer: %.1f frames/s (draw median %.1f ms), real-time factor %.2f (%.2f s simulated in %.2f s), step "
              "median %.3f ms; run --no-render: step median %.3f ms (ratio %.3f)\n",
              fps, view["timing_ms"]["render"]["median"].get<double>(), sim / wall, sim, wall, view_step, run_step,
              view_step / run_step);
  EXPECT_LE(view_step, 1.10 * run_step);
}

}  // namespace
