// The render thread of `octocut run` (issue 20, item 4). Unit checks with a stand-in renderer (no EGL): frames come
// out in push order, the renderer is made, used and destroyed on one thread other than the caller's, the queue is
// bounded, a failure to start is the constructor's, a failure part-way keeps the frames before it. End to end through
// run_scene with the EGL renderer: the threaded frames are byte for byte those of the same World's snapshots rendered
// on the test's own thread, one per `render.every` steps plus the first, and a renderer that fails at frame 3 leaves a
// failed report with frames 0-2 intact.
#include <gtest/gtest.h>

#include <atomic>
#include <csignal>
#include <chrono>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "common/report_util.hpp"
#include "common/temp_dir.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/render/frame_writer.hpp"
#include "octocut/engine/render/render_thread.hpp"
#include "octocut/engine/render/renderer.hpp"
#include "octocut/engine/run/run.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace octocut::engine {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// ---- a stand-in renderer -------------------------------------------------------------------------------------------

/// What the stand-in renderer saw, shared with the test.
struct Trace {
  std::thread::id made_on, destroyed_on;
  std::vector<std::thread::id> rendered_on;
  std::atomic<int> in_flight{0}, most_in_flight{0};  ///< snapshots alive (queued or drawing), and the most at once
};

/// Draws a 1 x 1 image whose red byte is the scene's width (the tests put the frame number there), and lowers
/// `Trace::in_flight`, which the test raises before each push; throws at the frame numbered `fail_at`.
class FakeRenderer final : public Renderer {
 public:
  FakeRenderer(Trace& trace, int fail_at, int delay_ms) : m_trace(trace), m_fail_at(fail_at), m_delay_ms(delay_ms) {
    m_trace.made_on = std::this_thread::get_id();
  }
  ~FakeRenderer() override { m_trace.destroyed_on = std::this_thread::get_id(); }
  Image render(const RenderScene& scene) override {
    m_trace.rendered_on.push_back(std::this_thread::get_id());
    std::this_thread::sleep_for(std::chrono::milliseconds(m_delay_ms));
    --m_trace.in_flight;
    if (scene.width == m_fail_at) throw RenderError("OpenGL: drawing: GL_OUT_OF_MEMORY (0x0505)");
    return Image{1, 1, {std::uint8_t(scene.width), 0, 0}};
  }
  [[nodiscard]] std::string description() const override { return "fake"; }

 private:
  Trace& m_trace;
  int m_fail_at, m_delay_ms;
};

/// Pushes frames 0..n-1 (the frame number as the scene's width), counting snapshots in flight.
void push_frames(RenderThread& thread, Trace& trace, int n) {
  for (int i = 0; i < n; ++i) {
    RenderScene scene;
    scene.width = i;
    const int now = ++trace.in_flight;
    trace.most_in_flight = std::max(trace.most_in_flight.load(), now);
    thread.push(std::move(scene));
  }
}

TEST(RenderThread, FramesInOrderOnOneThreadWithABoundedQueue) {
  Trace trace;
  std::vector<long> indices;
  std::vector<int> reds;
  {
    RenderThread thread([&] { return std::make_unique<FakeRenderer>(trace, -1, 2); },
                        [&](long index, Image image) {
                          indices.push_back(index);
                          reds.push_back(image.rgb.at(0));
                        },
                        2);
    EXPECT_EQ(thread.description(), "fake");
    push_frames(thread, trace, 20);
    thread.finish();
    EXPECT_EQ(thread.render_ms().size(), 20u);
    EXPECT_EQ(thread.wait_ms().size(), 20u);
    // The renderer (2 ms a frame) is slower than the pushes: the caller waited for room.
    double waited = 0.0;
    for (double ms : thread.wait_ms()) waited += ms;
    EXPECT_GT(waited, 0.0);
    thread.finish();  // idempotent
  }
  for (int i = 0; i < 20; ++i) {
    EXPECT_EQ(indices.at(std::size_t(i)), i);
    EXPECT_EQ(reds.at(std::size_t(i)), i);
  }
  // Made, used and destroyed on one thread, not the caller's.
  EXPECT_NE(trace.made_on, std::this_thread::get_id());
  EXPECT_EQ(trace.destroyed_on, trace.made_on);
  for (const std::thread::id& id : trace.rendered_on) EXPECT_EQ(id, trace.made_on);
  // At most the queue's 2 snapshots, one being drawn and the one being pushed are alive at once.
  EXPECT_LE(trace.most_in_flight.load(), 4);
}

TEST(RenderThread, AFailureToStartIsTheConstructors) {
  std::thread::id tried_on;
  try {
    RenderThread thread(
        [&]() -> std::unique_ptr<Renderer> {
          tried_on = std::this_thread::get_id();
          throw RenderError("EGL: no display: EGL_NOT_INITIALIZED (0x3001)");
        },
        {});
    FAIL() << "the constructor returned";
  } catch (const RenderError& e) {
    EXPECT_EQ(std::string(e.what()), "EGL: no display: EGL_NOT_INITIALIZED (0x3001)");
  }
  EXPECT_NE(tried_on, std::this_thread::get_id());
}

TEST(RenderThread, AFailurePartWayKeepsTheFramesBeforeIt) {
  Trace trace;
  std::vector<long> indices;
  RenderThread thread([&] { return std::make_unique<FakeRenderer>(trace, 5, 0); },
                      [&](long index, Image) { indices.push_back(index); });
  // Pushing goes on until the failure is seen (at the latest by finish()), whose message is the renderer's.
  std::string error;
  try {
    push_frames(thread, trace, 50);
    thread.finish();
  } catch (const RenderError& e) {
    error = e.what();
  }
  EXPECT_EQ(error, "OpenGL: drawing: GL_OUT_OF_MEMORY (0x0505)");
  EXPECT_EQ(indices, (std::vector<long>{0, 1, 2, 3, 4}));
  EXPECT_EQ(thread.render_ms().size(), 5u);
  EXPECT_THROW(thread.finish(), RenderError);
  EXPECT_EQ(trace.destroyed_on, trace.made_on);
}

// ---- through run_scene, with the EGL renderer ----------------------------------------------------------------------

// A block that sags under gravity and is punched at step 3, drawn every 2 steps: 7 steps, frames after steps 0, 2,
// 4, 6; the tissue's topology changes between frames 1 and 2.
const char* kBlock = R"({
  "name": "punched block", "duration": 0.007,
  "solver": {"dt": 0.001, "threads": 1},
  "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}},
             "material": {"young_modulus": 2e4, "poisson_ratio": 0.45},
             "octree": {"root": {"min": [-0.001, -0.001, -0.001], "size": 0.012}, "base_level": 3, "max_level": 4},
             "material_graph": {"cell_size": 0.001},
             "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 0.0005]}}]},
  "tools": [{"name": "punch", "blade": {"cylinder": {"radius": 0.002, "height": 0.02, "segments": 24}},
             "keyframes": [{"t": 0, "position": [0.005, 0.005, 0.005]}], "cuts": [{"t": 0.003}]}],
  "render": {"enabled": true, "width": 128, "height": 96, "every": 2, "msaa": 4,
             "camera": {"position": [0.005, -0.008, 0.026], "target": [0.005, 0.005, 0.008], "fov_deg": 40}},
  "output": {"frames": true}
})";

class RenderThreadRun : public octocut::test::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    if (!renderer_available()) GTEST_SKIP() << "built without EGL";
    m_scene = load_scene(write("block.json", kBlock).string());
  }

  /// The truth: the same World stepped here, its snapshots rendered on this thread, one per `every` steps plus the
  /// first at rest.
  std::vector<Image> single_threaded_frames() const {
    World world(m_scene, WorldOptions{.render = true});
    const std::unique_ptr<Renderer> renderer = make_renderer();
    std::vector<Image> frames{renderer->render(world.render_scene())};
    while (!world.done()) {
      world.step();
      if (world.steps() % m_scene.render.every == 0) frames.push_back(renderer->render(world.render_scene()));
    }
    return frames;
  }

  Scene m_scene;
};

TEST_F(RenderThreadRun, FramesEqualThoseRenderedOnOneThread) {
  const std::vector<Image> truth = single_threaded_frames();
  RunOptions options;
  options.out_dir = (m_dir / "out").string();
  const RunResult result = run_scene(m_scene, options);
  ASSERT_EQ(result.exit_code, 0) << result.error;
  const json report = test::read_json(m_dir / "out/report.json");
  const long steps = report["steps"].get<long>();
  EXPECT_EQ(steps, 7);
  ASSERT_EQ(long(truth.size()), steps / 2 + 1);
  EXPECT_EQ(report["frames"]["rendered"].get<long>(), steps / 2 + 1);
  EXPECT_EQ(report["frames"]["written"].get<long>(), steps / 2 + 1);
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const fs::path file = frame_path(m_dir / "out/frames", long(i));
    const Image frame = decode_png(read_file(file), file.string());
    EXPECT_EQ(frame.width, truth[i].width);
    EXPECT_TRUE(frame.rgb == truth[i].rgb) << file;
  }
  EXPECT_FALSE(fs::exists(frame_path(m_dir / "out/frames", long(truth.size()))));
  // The frames differ over time (the cut shows), so equal frames are not a constant image.
  EXPECT_FALSE(truth.front().rgb == truth.back().rgb);
  // The snapshot is timed on the simulation thread, the drawing on the render thread, per frame.
  EXPECT_GT(report["timing_ms"]["snapshot"]["max"].get<double>(), 0.0);
  EXPECT_GT(report["timing_ms"]["render"]["median"].get<double>(), 0.0);
  EXPECT_GE(report["timing_ms"]["render_wait"]["max"].get<double>(), 0.0);
}

TEST_F(RenderThreadRun, ARenderFailurePartWayFailsTheRunWithTheFramesBeforeIt) {
  const std::vector<Image> truth = single_threaded_frames();
  // The EGL renderer, failing at its fourth frame as a lost context would.
  class FailingAt3 final : public Renderer {
   public:
    Image render(const RenderScene& scene) override {
      if (m_frames++ == 3) throw RenderError("OpenGL: drawing: GL_OUT_OF_MEMORY (0x0505)");
      return m_inner->render(scene);
    }
    [[nodiscard]] std::string description() const override { return m_inner->description(); }

   private:
    std::unique_ptr<Renderer> m_inner = make_renderer();
    int m_frames = 0;
  };
  RunOptions options;
  options.out_dir = (m_dir / "out").string();
  options.renderer_factory = [] { return std::make_unique<FailingAt3>(); };
  const RunResult result = run_scene(m_scene, options);
  EXPECT_EQ(result.exit_code, 1);
  const json report = test::read_json(m_dir / "out/report.json");
  EXPECT_EQ(report["status"], "failed");
  EXPECT_NE(report["error"].get<std::string>().find("GL_OUT_OF_MEMORY"), std::string::npos) << report["error"];
  EXPECT_EQ(report["frames"]["written"].get<long>(), 3);
  for (std::size_t i = 0; i < 3; ++i) {
    const fs::path file = frame_path(m_dir / "out/frames", long(i));
    EXPECT_TRUE(decode_png(read_file(file), file.string()).rgb == truth[i].rgb) << file;
  }
  EXPECT_FALSE(fs::exists(frame_path(m_dir / "out/frames", 3)));
  for (const auto& e : fs::directory_iterator(m_dir / "out/frames"))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
}

TEST_F(RenderThreadRun, SigintStopsTheRunAndJoinsTheThreadWithEveryFrameWhole) {
  // A long run, interrupted once two frames are on disk: the run fails with its report, the render thread is joined,
  // and the frames on disk are 0..n-1 without a gap, each a whole PNG, as many as the report says were written.
  m_scene.duration = 1000.0;  // far longer than the wait below
  m_scene.output.step_times = true;
  RunOptions options;
  options.out_dir = (m_dir / "out").string();
  std::thread interrupter([&] {
    for (int i = 0; i < 3000 && !fs::exists(frame_path(m_dir / "out/frames", 1)); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    std::raise(SIGINT);
  });
  const RunResult result = run_scene(m_scene, options);
  interrupter.join();
  EXPECT_EQ(result.exit_code, 1);
  const json report = test::read_json(m_dir / "out/report.json");
  EXPECT_EQ(report["status"], "failed");
  EXPECT_NE(report["error"].get<std::string>().find("interrupted"), std::string::npos) << report["error"];
  const long written = report["frames"]["written"].get<long>();
  EXPECT_GE(written, 2);
  long on_disk = 0;
  for (const auto& e : fs::directory_iterator(m_dir / "out/frames")) {
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
    ++on_disk;
  }
  EXPECT_EQ(on_disk, written);
  for (long i = 0; i < written; ++i) {
    const fs::path file = frame_path(m_dir / "out/frames", i);
    EXPECT_EQ(decode_png(read_file(file), file.string()).width, 128) << file;
  }
  // steps.csv is written after a failure too: the header and a row for each step run.
  std::istringstream steps(read_file(m_dir / "out/steps.csv"));
  long lines = 0;
  for (std::string line; std::getline(steps, line);) ++lines;
  EXPECT_EQ(lines, report["steps"].get<long>() + 1);
  EXPECT_GE(lines, 2);
}

TEST_F(RenderThreadRun, ARendererThatCannotStartFailsBeforeTheFirstStep) {
  RunOptions options;
  options.out_dir = (m_dir / "out").string();
  options.renderer_factory = []() -> std::unique_ptr<Renderer> {
    throw RenderError("EGL: no display: EGL_NOT_INITIALIZED (0x3001)");
  };
  const RunResult result = run_scene(m_scene, options);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.error.find("/render/enabled: cannot start the renderer: EGL: no display"), std::string::npos)
      << result.error;
  const json report = test::read_json(m_dir / "out/report.json");
  EXPECT_EQ(report["status"], "failed");
  EXPECT_EQ(report["steps"].get<long>(), 0);
  EXPECT_FALSE(fs::exists(m_dir / "out/frames"));
}

}  // namespace
}  // namespace octocut::engine
