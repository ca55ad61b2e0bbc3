// Benchmark (label `bench`, not in CI): `octocut view` on meniscus_punch under Xvfb and Mesa llvmpipe for a fixed
// wall time with nobody touching it, against `octocut run --no-render` of the same scene without its cuts, in three
// alternating rounds. Prints the viewer's frame rate and real-time factor, and checks that the simulation thread's
// median step time stays within 10 % of the headless run's (the window must not slow the simulation down). Figures
// in docs/RESULTS.md.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

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

// One viewer session of `seconds` wall seconds, nobody touching it: its report.
json view_session(const fs::path& dir, const std::string& scene, double seconds) {
  octocut::test::Xvfb xvfb(dir / "xvfb.log");
  EXPECT_FALSE(xvfb.display().empty()) << read_text(dir / "xvfb.log");
  octocut::test::Child viewer({OCTOCUT_EXE, "view", scene, "--out", (dir / "view").string()},
                              {"DISPLAY=" + xvfb.display()}, dir / "view.log");
  const std::string search = "DISPLAY=" + xvfb.display() + " timeout 30 xdotool search --sync --name octocut >/dev/null";
  EXPECT_EQ(std::system(search.c_str()), 0) << read_text(dir / "view.log");
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const std::string esc = "DISPLAY=" + xvfb.display() + " timeout 10 xdotool search --name octocut key Escape";
  EXPECT_EQ(std::system(esc.c_str()), 0);
  EXPECT_EQ(viewer.wait_exit(std::chrono::seconds(60)), 0) << read_text(dir / "view.log");
  return read_json(dir / "view" / "report.json");
}

TEST_F(ViewBench, FrameRateRealTimeFactorAndStepTime) {
  // Three rounds, each a viewer session and then the same scene headless for the simulated time the session
  // reached, without the timeline's cuts (the viewer holds the tool): the machine's load drifts, so each viewer
  // session is compared with the headless run beside it, and the median of the rounds' ratios is checked.
  const std::string scene = std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/meniscus_punch.json";
  const double seconds = std::getenv("OCTOCUT_VIEW_BENCH_S") ? std::atof(std::getenv("OCTOCUT_VIEW_BENCH_S")) : 15.0;
  std::vector<double> ratios;
  for (int round = 0; round < 3; ++round) {
    const fs::path dir = m_dir / ("round" + std::to_string(round));
    fs::create_directories(dir);
    const json view = view_session(dir, scene, seconds);
    const double wall = view["wall_time_s"].get<double>(), sim = view["sim_time_s"].get<double>();
    const double fps = view["frames"]["rendered"].get<double>() / wall;
    const double view_step = view["timing_ms"]["step"]["median"].get<double>();
    const octocut::test::CommandResult r = octocut::test::run_octocut(
        "run '" + scene + "' --no-render --quiet --set '/tools/0/cuts=[]' --set /duration=" + std::to_string(sim) +
        " --out '" + (dir / "run").string() + "'");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const double run_step = read_json(dir / "run" / "report.json")["timing_ms"]["step"]["median"].get<double>();
    ratios.push_back(view_step / run_step);
    std::printf("round %d: viewer %.1f frames/s (draw median %.1f ms), real-time factor %.3f (%.3f s simulated in "
                "%.2f s), step median %.3f ms; run --no-render step median %.3f ms; ratio %.3f\n",
                round, fps, view["timing_ms"]["render"]["median"].get<double>(), sim / wall, sim, wall, view_step,
                run_step, view_step / run_step);
  }
  std::sort(ratios.begin(), ratios.end());
  std::printf("median ratio of the viewer's step time to the headless run's: %.3f\n", ratios[1]);
  EXPECT_LE(ratios[1], 1.10);
}

}  // namespace
