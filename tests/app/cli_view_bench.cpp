// Benchmark (label `bench`, not in CI): `octocut view` on meniscus_punch under Xvfb and Mesa llvmpipe, with the punch
// in the hand pushing the meniscus' rim (its collide is on), against `octocut run --no-render` doing the same work:
// the replay of the session the viewer recorded. Prints the viewer's frame rate and real-time factor, and checks that
// the simulation thread's median step time stays within 10 % of the headless replay's (the window must not slow the
// simulation down). Figures in docs/RESULTS.md, section "Viewer".
//
// Why a replay: the step time of this scene depends on what the punch does (pressing into the rim, contact makes
// the step several times dearer than the tissue alone), so the headless side must run the same poses at the same
// steps. The replay does: it reproduces the viewer's report (contact forces included) apart from timings, which
// this benchmark checks too. An earlier version compared a viewer nobody touched against the keyframed scene; X
// reported the pointer's position under the newly mapped window, the viewer took it for a move and put the punch
// onto the tissue, and one of three rounds measured 832 ms per step against a headless run without contact.
//
//   ctest --test-dir build -L bench -R ViewBench -V     (-V: ctest shows the output of a passing test too)
//   OCTOCUT_VIEW_BENCH_S=20 OCTOCUT_VIEW_BENCH_ROUNDS=5 OCTOCUT_VIEW_BENCH_MIN_STEPS=300 build/bin/app_cli_view_bench
//
// The last line of its output is the summary: ratio, frames per second, real-time factor, load average.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "common/cli_util.hpp"
#include "common/report_util.hpp"
#include "octocut/engine/io/io.hpp"
#include "common/temp_dir.hpp"
#include "common/xvfb.hpp"
#include "octocut/engine/render/camera.hpp"

namespace {

namespace fs = std::filesystem;
using octocut::test::read_json;
using nlohmann::json;

constexpr int kWidth = 1280, kHeight = 720;  // the scene's render size, the viewer's window

// The 1-minute load average (/proc/loadavg), -1 where there is none.
double load_average() {
  std::ifstream in("/proc/loadavg");
  double l = -1.0;
  in >> l;
  return l;
}

double env_number(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v != nullptr ? std::atof(v) : fallback;
}

// The step count of the viewer's last status line in its log (0 before the first).
long logged_steps(const fs::path& log) {
  static const std::regex line(R"(\[view\] t = [0-9.]+ s  steps ([0-9]+))");
  const std::string text = octocut::engine::read_file(log);
  long steps = 0;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), line); it != std::sregex_iterator(); ++it)
    steps = std::stol((*it)[1]);
  return steps;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n == 0 ? 0.0 : (n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]));
}

// The xdotool script of one session, `seconds` long: the pointer onto the rim where the scene's punch takes its
// first bite (the punch lands on the tissue there), three W presses (0.8 mm deeper along the view ray: the scene's
// keyframes press 0.33 mm below their approach height), then along the rim through the scene's other bite
// positions and back, in small moves.
std::string hand_script(double seconds) {
  octocut::engine::Camera camera;  // the scene's camera (render.camera of meniscus_punch.json)
  camera.position = {0.006, 0.017, 0.008};
  camera.target = {0.0, -0.007, 0.0};
  camera.up = {0.0, 0.0, 1.0};
  camera.fov_deg = 75.0;
  const std::vector<Eigen::Vector3d> bites = {{-0.007501, -0.005485, 0.0006}, {-0.003375, -0.006391, 0.0006},
                                              {0.001136, -0.006577, 0.0006},  {0.005517, -0.006024, 0.0006},
                                              {0.009271, -0.004786, 0.0006},  {0.011982, -0.002958, 0.0006}};
  std::vector<Eigen::Vector2d> path;
  const auto pixel = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d q = octocut::engine::project_to_pixel(camera, kWidth, kHeight, p);
    return Eigen::Vector2d(q.x(), q.y());
  };
  for (std::size_t i = 0; i + 1 < bites.size(); ++i)
    for (int k = 0; k < 8; ++k) path.push_back(pixel(bites[i] + (bites[i + 1] - bites[i]) * (k / 8.0)));
  for (std::size_t i = path.size(); i-- > 1;) path.push_back(path[i - 1]);  // and back
  const double pause = std::max(0.05, (seconds - 3.0) / double(path.size()));
  std::ostringstream s;
  s << "search --onlyvisible --name octocut";  // the window, %1 below: pointer positions in its pixels
  const auto move = [&](const Eigen::Vector2d& p) {
    s << " mousemove --window %1 " << int(p.x()) << ' ' << int(p.y());
  };
  move(path.front());
  s << " sleep 1 key w sleep 0.3 key w sleep 0.3 key w sleep 0.4";
  for (const Eigen::Vector2d& p : path) {
    move(p);
    s << " sleep " << pause;
  }
  return s.str();
}

struct Round {
  double ratio = 0.0, fps = 0.0, realtime = 0.0, view_step = 0.0, run_step = 0.0, load = 0.0;
};

class ViewBench : public octocut::test::TempDirTest {
 protected:
  // One viewer session with the hand script, then the headless replay of what it recorded.
  Round round(const fs::path& dir, const std::string& scene, double seconds) {
    Round r;
    r.load = load_average();
    octocut::test::Xvfb xvfb(dir / "xvfb.log", "1600x900x24");  // the whole window on the screen
    EXPECT_FALSE(xvfb.display().empty()) << octocut::engine::read_file(dir / "xvfb.log");
    const std::string x = "DISPLAY=" + xvfb.display() + " timeout 60 xdotool ";
    // The pointer off the window's area (1280×720 at the top left of 1600×900) before the window opens.
    EXPECT_EQ(std::system((x + "mousemove 1500 850").c_str()), 0);
    const fs::path record = dir / "s.json";
    octocut::test::Child viewer(
        {OCTOCUT_EXE, "view", scene, "--record", record.string(), "--out", (dir / "view").string()},
        {"DISPLAY=" + xvfb.display()}, dir / "view.log");
    EXPECT_EQ(std::system((x + "search --sync --onlyvisible --name octocut >/dev/null").c_str()), 0)
        << octocut::engine::read_file(dir / "view.log");
    EXPECT_EQ(std::system((x + hand_script(seconds)).c_str()), 0);
    // A median needs steps: on a loaded machine the session goes on (the punch held where the script left it) until
    // it has OCTOCUT_VIEW_BENCH_MIN_STEPS steps, for at most a minute more.
    const long min_steps = long(env_number("OCTOCUT_VIEW_BENCH_MIN_STEPS", 150.0));
    for (int i = 0; i < 600 && logged_steps(dir / "view.log") < min_steps; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    EXPECT_EQ(std::system((x + "search --name octocut key Escape").c_str()), 0);
    EXPECT_EQ(viewer.wait_exit(std::chrono::seconds(120)), 0) << octocut::engine::read_file(dir / "view.log");
    const json view = read_json(dir / "view" / "report.json");
    const octocut::test::CommandResult run = octocut::test::run_octocut(
        "run '" + scene + "' --replay '" + record.string() + "' --no-render --quiet --out '" + (dir / "run").string() +
        "'");
    EXPECT_EQ(run.exit_code, 0) << run.output;
    const json headless = read_json(dir / "run" / "report.json");
    // The same work: the same steps and the same contact (the punch pushed the rim in both, equally).
    EXPECT_EQ(view["steps"], headless["steps"]);
    EXPECT_EQ(view["contact"], headless["contact"]);
    EXPECT_GT(view["contact"]["tools"]["punch"]["force_n"]["max"].get<double>(), 0.0)
        << "the punch never touched the tissue: " << view["contact"].dump();
    r.view_step = view["timing_ms"]["step"]["median"].get<double>();
    r.run_step = headless["timing_ms"]["step"]["median"].get<double>();
    r.ratio = r.view_step / r.run_step;
    r.fps = view["frames"]["rendered"].get<double>() / view["wall_time_s"].get<double>();
    r.realtime = view["realtime_factor"].get<double>();
    std::printf("round: viewer %.1f frames/s (draw median %.1f ms), real-time factor %.3f (%.3f s simulated in "
                "%.1f s, %ld steps, punch force max %.3f N); step median viewer %.2f ms, run --replay --no-render "
                "%.2f ms; ratio %.3f; load average %.2f -> %.2f\n",
                r.fps, view["timing_ms"]["render"]["median"].get<double>(), r.realtime,
                view["sim_time_s"].get<double>(), view["wall_time_s"].get<double>(), view["steps"].get<long>(),
                view["contact"]["tools"]["punch"]["force_n"]["max"].get<double>(), r.view_step, r.run_step, r.ratio,
                r.load, load_average());
    std::fflush(stdout);
    return r;
  }
};

TEST_F(ViewBench, FrameRateRealTimeFactorAndStepTime) {
  const std::string scene = std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/meniscus_punch.json";
  const double seconds = env_number("OCTOCUT_VIEW_BENCH_S", 15.0);
  const int rounds = std::max(1, int(env_number("OCTOCUT_VIEW_BENCH_ROUNDS", 3.0)));
  std::vector<double> ratio, fps, realtime, load;
  for (int k = 0; k < rounds; ++k) {
    const fs::path dir = m_dir / ("round" + std::to_string(k));
    fs::create_directories(dir);
    const Round r = round(dir, scene, seconds);
    if (HasFailure()) return;
    ratio.push_back(r.ratio);
    fps.push_back(r.fps);
    realtime.push_back(r.realtime);
    load.push_back(r.load);
  }
  std::printf("ViewBench meniscus_punch %dx%d, %d rounds of %.0f s (medians): step ratio viewer/headless %.3f "
              "(goal <= 1.10), %.1f frames/s, real-time factor %.3f, load average %.2f\n",
              kWidth, kHeight, rounds, seconds, median(ratio), median(fps), median(realtime), median(load));
  EXPECT_LE(median(ratio), 1.10);
}

}  // namespace
