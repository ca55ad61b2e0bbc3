// `octocut view` under Xvfb and Mesa llvmpipe, driven by real X events (xdotool): a session in which the mouse moves
// the punch over the meniscus, a click cuts and Esc closes; the recorded session replays headless to the same cuts;
// a screenshot after the cut matches a golden image (tolerances as in tests/engine/render/golden_test.cpp) and shows
// the hole that one before the cut does not; no display is bad input. Each test starts its own Xvfb and kills
// everything it started, also when it fails.
//
// Regenerate the golden screenshot on purpose with OCTOCUT_REGENERATE_GOLDEN=1; review it before committing.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
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
#include "common/temp_dir.hpp"
#include "common/xvfb.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/render/camera.hpp"
#include "octocut/engine/render/frame_writer.hpp"
#include "octocut/engine/run/session.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace {

namespace fs = std::filesystem;

// How much longer every wait may take in a Debug or sanitizer build, where the viewer runs 10-50 times slower: the
// deadlines below are for the Release build CI runs; the tests' checks do not depend on time.
#if defined(__SANITIZE_ADDRESS__) || !defined(NDEBUG)
constexpr int kSlow = 15;
#else
constexpr int kSlow = 1;
#endif
std::chrono::seconds deadline(std::chrono::seconds s) { return kSlow * s; }

// The viewer's environment: its display, Mesa's software rasteriser, and in an AddressSanitizer build no leak check
// at exit: a library loaded at run time for the window's GL context and unloaded at exit leaks 240 bytes in 3 blocks,
// which LeakSanitizer can only attribute to "<unknown module>"; memory errors are still reported, and every other
// test keeps the leak check.
std::vector<std::string> viewer_env(const std::string& display) {
  std::vector<std::string> env{"DISPLAY=" + display, "LIBGL_ALWAYS_SOFTWARE=1"};
#if defined(__SANITIZE_ADDRESS__)
  env.push_back("ASAN_OPTIONS=detect_leaks=0");
#endif
  return env;
}
using octocut::test::read_json;
using nlohmann::json;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
using octocut::test::Child;
using octocut::test::CommandResult;
using octocut::test::Xvfb;
using octocut::test::run_octocut;

constexpr int kWidth = 800, kHeight = 450;  // the viewer's window, pixels

class CliViewTest : public octocut::test::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    m_xvfb = std::make_unique<Xvfb>(m_dir / "xvfb.log");
    ASSERT_FALSE(m_xvfb->display().empty()) << "Xvfb did not start: " << octocut::engine::read_file(m_dir / "xvfb.log");
  }
  void TearDown() override {
    m_viewer.reset();
    // A failed test leaves its files (log, session, report, screenshots) in the temp folder for a look.
    if (HasFailure()) {
      const fs::path keep = fs::temp_directory_path() / "octocut_view_test_failed";
      fs::remove_all(keep);
      fs::copy(m_dir, keep, fs::copy_options::recursive);
      std::fprintf(stderr, "files of the failed test: %s\n", keep.c_str());
    }
    m_xvfb.reset();
    TempDirTest::TearDown();
  }

  // Runs xdotool on the test's display (at most 10 s, times kSlow); its output.
  std::string xdotool(const std::string& arguments) const {
    const std::string command = "DISPLAY=" + m_xvfb->display() + " timeout " + std::to_string(10 * kSlow) +
                                " xdotool " + arguments + " 2>&1";
    std::string out;
    FILE* pipe = popen(command.c_str(), "r");
    if (pipe == nullptr) return out;
    char buffer[256];
    while (std::fgets(buffer, sizeof buffer, pipe)) out += buffer;
    pclose(pipe);
    return out;
  }

  // The viewer's log.
  [[nodiscard]] std::string log() const { return octocut::engine::read_file(m_dir / "view.log"); }

  // The simulated time of the viewer's last status line, s (-1 before the first).
  [[nodiscard]] double sim_time() const {
    static const std::regex line(R"(\[view\] t = ([0-9.]+) s)");
    double t = -1.0;
    const std::string text = log();
    for (auto it = std::sregex_iterator(text.begin(), text.end(), line); it != std::sregex_iterator(); ++it)
      t = std::stod((*it)[1]);
    return t;
  }

  // Waits until `ready()` or the deadline; false on the deadline or when the viewer died.
  template <class F>
  bool wait_for(F ready, std::chrono::seconds timeout) {
    const auto end = Clock::now() + timeout;
    while (Clock::now() < end) {
      if (ready()) return true;
      if (m_viewer && !m_viewer->running()) return ready();
      std::this_thread::sleep_for(50ms);
    }
    return false;
  }

  std::unique_ptr<Xvfb> m_xvfb;
  std::unique_ptr<Child> m_viewer;
};

// The pixel (x, y) of an RGB8 image.
const std::uint8_t* rgb(const octocut::engine::Image& image, int x, int y) {
  return &image.rgb[3 * (std::size_t(y) * image.width + x)];
}

// Cut faces: the renderer's fresh-tissue red (0.78, 0.12, 0.10) lit, red well above green and blue; intact tissue is
// pink (0.86, 0.58, 0.56), the background dark grey (0.08, 0.08, 0.10).
bool is_cut_face(const std::uint8_t* p) { return p[0] > 60 && p[1] < 0.4 * p[0] && p[2] < 0.4 * p[0]; }
bool is_tissue(const std::uint8_t* p) { return p[0] > 100 && p[1] > 0.45 * p[0] && p[2] > 0.45 * p[0]; }

// Within `radius` pixels of (cx, cy): the pixels that show cut faces in `after`, and those that showed tissue in
// `before` and show cut faces or no tissue (the background through the hole) in `after`.
std::pair<int, int> hole_pixels(const octocut::engine::Image& before, const octocut::engine::Image& after, double cx,
                                double cy, int radius) {
  int cut = 0, opened = 0;
  for (int y = std::max(0, int(cy) - radius); y < std::min(after.height, int(cy) + radius); ++y)
    for (int x = std::max(0, int(cx) - radius); x < std::min(after.width, int(cx) + radius); ++x) {
      cut += is_cut_face(rgb(after, x, y));
      opened += is_tissue(rgb(before, x, y)) && !is_tissue(rgb(after, x, y));
    }
  return {cut, opened};
}

TEST_F(CliViewTest, MouseCutRecordReplayAndScreenshot) {
  const std::string scene = std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/meniscus_punch.json";
  const fs::path record = m_dir / "s.json", out = m_dir / "o";
  m_viewer = std::make_unique<Child>(
      std::vector<std::string>{OCTOCUT_EXE, "view", scene, "--set", "/solver/gravity=[0,0,0]", "--set",
                               "/render/props=[]", "--set", "/tools/0/collide=false", "--set", "/render/camera/arthroscope=false", "--set",
                               "/render/camera/mask=false", "--set", "/render/camera/position=[0,-0.002,0.045]", "--set",
                               "/render/camera/target=[0,-0.002,0]", "--set", "/render/camera/up=[0,1,0]", "--set",
                               "/render/camera/fov_deg=45", "--record", record.string(), "--out", out.string(),
                               "--size", std::to_string(kWidth) + "x" + std::to_string(kHeight)},
      viewer_env(m_xvfb->display()), m_dir / "view.log");
  // Without gravity, and with the punch not colliding, the meniscus stays at rest, so that the images do not depend on
  // when they were taken; seen from above without the knee, so that the hole shows. The overrides are recorded in the session, and the replay
  // applies them. The window, then its first status line.
  const std::string window = xdotool("search --sync --onlyvisible --name 'octocut'");
  ASSERT_FALSE(window.empty()) << log();
  const std::string id = window.substr(0, window.find('\n'));
  ASSERT_TRUE(wait_for([&] { return sim_time() >= 0.0; }, deadline(40s))) << log();

  // A point in the middle of the meniscus' right horn, on the screen (clear of the panel): tissue under the mouse.
  octocut::engine::Camera camera;
  camera.position = {0.0, -0.002, 0.045};
  camera.target = {0.0, -0.002, 0.0};
  camera.up = {0.0, 1.0, 0.0};
  camera.fov_deg = 45.0;
  const Eigen::Vector3d punch = octocut::engine::project_to_pixel(camera, kWidth, kHeight, {0.018, 0.0017, 0.002});
  // --sync: xdotool returns once the pointer has moved, so that the X server has queued the motion before the key or
  // the click that follows (xdotool's runs are separate clients; a loaded server need not serve them in order).
  const std::string park = "mousemove --sync --window " + id + " " + std::to_string(kWidth - 20) + " 20";
  const std::string over = "mousemove --sync --window " + id + " " + std::to_string(int(punch.x())) + " " +
                           std::to_string(int(punch.y()));

  // Before: the tool parked off the tissue, a screenshot.
  xdotool(park);
  std::this_thread::sleep_for(300ms);
  xdotool("key F12");
  ASSERT_TRUE(wait_for([&] { return log().find("screenshot_000.png") != std::string::npos; }, deadline(10s))) << log();
  // The cut: the mouse over the tissue, a click.
  xdotool(over);
  std::this_thread::sleep_for(300ms);
  xdotool("click 1");
  ASSERT_TRUE(wait_for([&] { return log().find("[view] cut at") != std::string::npos; }, deadline(20s))) << log();
  // After: the tool parked again, a screenshot; then Esc.
  xdotool(park);
  std::this_thread::sleep_for(300ms);
  xdotool("key F12");
  ASSERT_TRUE(wait_for([&] { return log().find("screenshot_001.png") != std::string::npos; }, deadline(10s))) << log();
  xdotool("key Escape");
  ASSERT_EQ(m_viewer->wait_exit(deadline(20s)), 0) << log();

  // The session has the cut; the viewer's report has it too.
  const json session = read_json(record);
  int recorded_cuts = 0;
  for (const json& e : session["events"]) recorded_cuts += e["kind"] == "cut";
  EXPECT_EQ(recorded_cuts, 1) << session.dump();
  const json viewed = read_json(out / "report.json");
  ASSERT_EQ(viewed["cuts"].size(), 1u) << viewed["cuts"].dump();
  EXPECT_EQ(viewed["cuts"][0]["status"], "ok") << viewed["cuts"].dump();
  EXPECT_GT(viewed["cuts"][0]["removed_volume_m3"].get<double>(), 1e-10);

  // Replayed headless: the same cuts.
  const CommandResult r = run_octocut("run '" + scene + "' --replay '" + record.string() + "' --no-render --quiet --out '" +
                                      (m_dir / "replay").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json replayed = read_json(m_dir / "replay" / "report.json");
  ASSERT_EQ(replayed["cuts"].size(), viewed["cuts"].size());
  for (std::size_t i = 0; i < viewed["cuts"].size(); ++i) {
    const json &a = viewed["cuts"][i], &b = replayed["cuts"][i];
    EXPECT_EQ(a["status"], b["status"]);
    EXPECT_EQ(a["t"], b["t"]);
    const double va = a["removed_volume_m3"].get<double>(), vb = b["removed_volume_m3"].get<double>();
    EXPECT_LE(std::abs(va - vb), 1e-9 * std::abs(va)) << va << " vs " << vb;
  }
  EXPECT_EQ(viewed["steps"], replayed["steps"]);
  EXPECT_EQ(viewed["counts"], replayed["counts"]);

  // The hole: cut faces (red) around the punch after the cut, none before.
  const auto before = octocut::engine::decode_png(octocut::engine::read_file(out / "screenshot_000.png"), "before");
  const auto after = octocut::engine::decode_png(octocut::engine::read_file(out / "screenshot_001.png"), "after");
  ASSERT_EQ(after.width, kWidth);
  ASSERT_EQ(after.height, kHeight);
  // The punch (2 mm across, about 24 pixels here) opened the horn: tissue before, cut faces (the walls and the floor
  // of the hole) or the background through it after.
  const auto [cut_before, opened_before] = hole_pixels(before, before, punch.x(), punch.y(), 30);
  const auto [cut_after, opened_after] = hole_pixels(before, after, punch.x(), punch.y(), 30);
  EXPECT_EQ(cut_before, 0);
  EXPECT_EQ(opened_before, 0);
  EXPECT_GT(cut_after, 10);
  EXPECT_GT(opened_after, 100);

  // The screenshot against the golden image, within the golden tests' tolerances.
  const fs::path golden_dir = fs::path(OCTOCUT_SOURCE_DIR) / "tests/app/golden";
  const fs::path golden = golden_dir / "viewer_cut.png", tolerance_file = golden_dir / "viewer_cut.json";
  if (const char* regen = std::getenv("OCTOCUT_REGENERATE_GOLDEN"); regen != nullptr && std::string(regen) == "1") {
    fs::create_directories(golden_dir);
    octocut::engine::write_file_atomic(golden, octocut::engine::read_file(out / "screenshot_001.png"));
    if (!fs::exists(tolerance_file))
      octocut::engine::write_file_atomic(tolerance_file, "{\"threshold\": 2, \"max_diff\": 48, \"max_fraction\": 0.01}\n");
  }
  const auto reference = octocut::engine::decode_png(octocut::engine::read_file(golden), golden.string());
  const json tol = json::parse(octocut::engine::read_file(tolerance_file));
  ASSERT_EQ(reference.width, after.width);
  ASSERT_EQ(reference.height, after.height);
  int differing = 0, worst = 0;
  for (std::size_t i = 0; i < after.rgb.size(); i += 3) {
    int d = 0;
    for (int k = 0; k < 3; ++k) d = std::max(d, std::abs(int(after.rgb[i + k]) - int(reference.rgb[i + k])));
    worst = std::max(worst, d);
    differing += d > tol.at("threshold").get<int>();
  }
  EXPECT_LE(worst, tol.at("max_diff").get<int>());
  EXPECT_LE(double(differing) / double(after.width * after.height), tol.at("max_fraction").get<double>());
}

// A 2 cm block of tissue (the octree's root cube, 5 mm leaves) with a fixed base and Poisson's ratio 0, and a platen (30 mm square, its face at the tool
// origin) that collides and is held. Without gravity, heavily damped (rayleigh_mass 600 1/s against a first mode of
// 350 rad/s), seen from straight above.
constexpr const char* kPlatenScene = R"({
  "name": "platen_push",
  "duration": 1000,
  "solver": {"mode": "dynamic", "dt": 0.002, "gravity": [0, 0, 0], "threads": 1},
  "object": {"surface": {"box": {"min": [-0.01, -0.01, 0], "max": [0.01, 0.01, 0.02]}},
             "material": {"young_modulus": 20000, "poisson_ratio": 0.0, "density": 1000, "rayleigh_mass": 600},
             "octree": {"root": {"min": [-0.01, -0.01, 0], "size": 0.02}, "base_level": 2, "max_level": 2},
             "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 0.0005]}}]},
  "tools": [{"name": "platen", "mesh": "platen.obj", "blade": {"cylinder": {"radius": 0.001, "height": 0.001}},
             "keyframes": [{"t": 0, "position": [0, 0, 0.05]}], "collide": true}],
  "probes": [{"name": "top", "point": [0, 0, 0.0199]}],
  "render": {"enabled": true, "width": 800, "height": 600, "msaa": 0,
             "camera": {"position": [0, 0, 0.1], "target": [0, 0, 0.02], "up": [0, 1, 0], "fov_deg": 45}}
})";

// The platen: a closed box from (-15, -15, 0) to (15, 15, 10) mm, outward-facing triangles.
constexpr const char* kPlatenObj =
    "v -0.015 -0.015 0\nv 0.015 -0.015 0\nv 0.015 0.015 0\nv -0.015 0.015 0\n"
    "v -0.015 -0.015 0.01\nv 0.015 -0.015 0.01\nv 0.015 0.015 0.01\nv -0.015 0.015 0.01\n"
    "f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n";

// The held tool pushes tissue. The mouse puts the platen on the block's top face (the view ray through the window's
// centre is the block's axis), two W presses move it 2 × 0.8 mm deeper (1 % of the eye-target distance each), and
// Esc ends the session once it has settled. With nu = 0 the block is in uniaxial compression whatever its base, so
// the independent expectation is Hooke's law: the top moves down by u and the platen carries F = E A u / h (A the
// top's area, h the height). The penalty lets the platen sink in by F / (k A), a few per cent of u here, so u is just
// under the hand's indentation d; no sample is ever deeper than the largest move the hand made at once.
TEST_F(CliViewTest, HeldToolPushesTissue) {
  write("platen.obj", kPlatenObj);
  const fs::path scene = write("platen.json", kPlatenScene), record = m_dir / "s.json", out = m_dir / "o";
  m_viewer = std::make_unique<Child>(
      std::vector<std::string>{OCTOCUT_EXE, "view", scene.string(), "--set", "/render/overlays/contacts=true", "--record",
                               record.string(), "--out", out.string()},
      viewer_env(m_xvfb->display()), m_dir / "view.log");
  const std::string window = xdotool("search --sync --onlyvisible --name 'octocut'");
  ASSERT_FALSE(window.empty()) << log();
  const std::string id = window.substr(0, window.find('\n'));
  ASSERT_TRUE(wait_for([&] { return sim_time() >= 0.0; }, deadline(40s))) << log();
  xdotool("mousemove --sync --window " + id + " 400 300");  // the window's centre, right of the panel
  // The placement must be a frame of its own before the first W (on a loaded machine a frame can take longer than
  // 500 ms, and the placement and the press then land in one frame): wait for 0.1 s of simulated time as well.
  const double placed = sim_time();  // s
  std::this_thread::sleep_for(500ms);
  ASSERT_TRUE(wait_for([&] { return sim_time() >= placed + 0.1; }, deadline(10s))) << log();
  xdotool("key w");
  // The block settles under the first press before the second (0.2 s, 7 settling times): the penetration check below
  // takes one press at a time. In Release 600 ms of wall time is more than that; slower builds wait for it.
  const double first = sim_time();  // s
  std::this_thread::sleep_for(600ms);
  ASSERT_TRUE(wait_for([&] { return sim_time() >= first + 0.2; }, deadline(10s))) << log();
  xdotool("key w");
  // Simulated time follows the wall clock (the block's steps take well under its 2 ms): 3 s is 100 settling times.
  // Debug and sanitizer builds step about a hundred times slower: 1 s, still 33 settling times.
  const double pushed = sim_time(), hold = kSlow > 1 ? 1.0 : 3.0;  // s
  ASSERT_TRUE(wait_for([&] { return sim_time() >= pushed + hold; }, deadline(20s))) << log();
  xdotool("key F12");
  ASSERT_TRUE(wait_for([&] { return log().find("screenshot_000.png") != std::string::npos; }, deadline(10s))) << log();
  xdotool("key Escape");
  ASSERT_EQ(m_viewer->wait_exit(deadline(20s)), 0) << log();

  // What the hand did, from the session: placed on the top face (z = 20 mm) above the axis, then d deeper.
  const json session = read_json(record);
  std::vector<json> poses;
  for (const json& e : session["events"])
    if (e["kind"] == "pose") poses.push_back(e["pose"]["position"]);
  ASSERT_GE(poses.size(), 2u) << session.dump();  // two W presses in one frame (a slow window) make one move
  EXPECT_NEAR(poses.front()[2].get<double>(), 0.02, 1e-7);
  EXPECT_LT(std::hypot(poses.back()[0].get<double>(), poses.back()[1].get<double>()), 1e-4);
  const double d = 0.02 - poses.back()[2].get<double>();  // m
  EXPECT_NEAR(d, 2 * 0.0008, 1e-6);
  double jump = 0.0;  // the largest move of the platen in one go, m
  for (std::size_t i = 1; i < poses.size(); ++i)
    jump = std::max(jump, poses[i - 1][2].get<double>() - poses[i][2].get<double>());

  const json report = read_json(out / "report.json");
  ASSERT_EQ(report["status"], "ok");
  EXPECT_EQ(report["stability"]["failed_steps"], 0);
  const double u = -report["probes"]["top"]["displacement"][2].get<double>();  // m, down
  const json force = report["contact"]["tools"]["platen"]["force_n"]["final"];
  const double E = 20000.0, A = 0.02 * 0.02, h = 0.02;
  // Pushed down, by a little less than the hand went down.
  EXPECT_GT(u, 0.9 * d);
  EXPECT_LT(u, d);
  // The tissue pushes the platen back up with Hooke's force for that displacement, and not sideways.
  EXPECT_NEAR(force[2].get<double>(), E * A * u / h, 0.02 * E * A * u / h) << force.dump();
  EXPECT_LT(std::hypot(force[0].get<double>(), force[1].get<double>()), 0.01 * force[2].get<double>());
  // Penetration: never deeper than the largest move the hand made at once (a press moves the platen 0.8 mm).
  EXPECT_LT(report["contact"]["max_penetration_m"].get<double>(), 1.05 * jump);

  // The contact overlay, asked for with --set: the top face's corner samples, pressed down by u, are drawn over the
  // platen as orange points (unlit 255, 140, 25), at the pixels the camera projects them to.
  const auto shot = octocut::engine::decode_png(octocut::engine::read_file(out / "screenshot_000.png"), "shot");
  octocut::engine::Camera camera;
  camera.position = {0.0, 0.0, 0.1};
  camera.target = {0.0, 0.0, 0.02};
  camera.up = {0.0, 1.0, 0.0};
  camera.fov_deg = 45.0;
  for (const double x : {-0.01, 0.01})
    for (const double y : {-0.01, 0.01}) {
      const Eigen::Vector3d p = octocut::engine::project_to_pixel(camera, shot.width, shot.height, {x, y, 0.02 - u});
      bool orange = false;
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) {
          const std::uint8_t* c = rgb(shot, int(p.x()) + dx, int(p.y()) + dy);
          orange |= c[0] > 240 && c[1] > 120 && c[1] < 160 && c[2] < 50;
        }
      EXPECT_TRUE(orange) << "no contact point drawn at the corner (" << x << ", " << y << ")";
    }
}

TEST(CliViewNoDisplay, ExitsTwoWithAClearMessage) {
  const std::string scene = std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/meniscus_punch.json";
  const CommandResult r = run_octocut("view '" + scene + "'", "env -u DISPLAY -u WAYLAND_DISPLAY");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("cannot open a window"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("DISPLAY"), std::string::npos) << r.output;
}

}  // namespace
