// Rendering end to end through `octocut run`: frames in order and bit-identical between runs, `render.every`, the
// report's render timings, a failure mid-run that keeps the frames written so far, EGL failing to start (exit 2 with
// the EGL error, never a crash), `--no-render` never touching EGL, render key validation; and the tissue surface
// builder against analytic values.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "common/cli_util.hpp"
#include "octocut/engine/render/frame_writer.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/render/render_builder.hpp"
#include "octocut/engine/render/renderer.hpp"
#include "octocut/sim/primitives.hpp"
#include "common/temp_dir.hpp"

namespace octocut::engine {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

using test::CommandResult;
using test::run_octocut;

const char* kCube = R"({
  "name": "cube", "duration": 0.006,
  "solver": {"dt": 0.001, "threads": 1},
  "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}},
             "material": {"young_modulus": 5e4, "poisson_ratio": 0.45},
             "octree": {"root": {"min": [0, 0, 0], "size": 0.016}, "base_level": 3},
             "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 1e-9]}}]},
  "render": {"enabled": true, "width": 96, "height": 64, "every": 2,
             "camera": {"arthroscope": true}, "overlays": {"octree": true, "dofs": true, "hanging": true}},
  "output": {"frames": true}
})";

class RenderCliTest : public octocut::test::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    m_scene = m_dir / "cube.json";
    std::ofstream(m_scene) << kCube;
  }
  CommandResult run(const std::string& out, const std::string& extra = "", const std::string& env = "") {
    return run_octocut("run '" + m_scene.string() + "' --quiet --out '" + (m_dir / out).string() + "' " + extra, env);
  }
  json report(const std::string& out) { return json::parse(read_file(m_dir / out / "report.json")); }
  fs::path m_scene;
};

TEST_F(RenderCliTest, FramesComeOutInOrderAndBitIdenticalBetweenRuns) {
  if (!renderer_available()) GTEST_SKIP() << "built without EGL";
  const CommandResult a = run("a"), b = run("b");
  ASSERT_EQ(a.exit_code, 0) << a.output;
  ASSERT_EQ(b.exit_code, 0) << b.output;
  // 6 steps, every 2: frames after steps 0, 2, 4, 6.
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(m_dir / "a/frames")) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"frame_000000.png", "frame_000001.png", "frame_000002.png",
                                             "frame_000003.png"}));
  for (const std::string& name : names) {
    const std::string fa = read_file(m_dir / "a/frames" / name), fb = read_file(m_dir / "b/frames" / name);
    EXPECT_EQ(fa, fb) << name;
    const Image image = decode_png(fa, name);
    EXPECT_EQ(image.width, 96);
    EXPECT_EQ(image.height, 64);
  }
  // The report counts and times them.
  const json r = report("a");
  EXPECT_EQ(r["status"], "ok");
  EXPECT_EQ(r["frames"]["rendered"].get<int>(), 4);
  EXPECT_EQ(r["frames"]["written"].get<int>(), 4);
  EXPECT_GT(r["timing_ms"]["render"]["median"].get<double>(), 0.0);
  EXPECT_GT(r["timing_ms"]["frame_write"]["median"].get<double>(), 0.0);
}

TEST_F(RenderCliTest, WithoutFramesNothingIsWrittenButFramesAreRendered) {
  if (!renderer_available()) GTEST_SKIP() << "built without EGL";
  const CommandResult r = run("n", "--set /output/frames=false --set /render/every=3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(m_dir / "n/frames"));
  EXPECT_EQ(report("n")["frames"]["rendered"].get<int>(), 3);
  EXPECT_EQ(report("n")["frames"]["written"].get<int>(), 0);
  // A renderer, but no frame writer without output.frames.
  EXPECT_EQ(report("n")["subsystems"]["renderer"], true);
  EXPECT_EQ(report("n")["subsystems"]["frame_writer"], false);
  // With frames: both; with --no-render: neither, and no EGL is touched (a forced EGL failure does not matter).
  ASSERT_EQ(run("w").exit_code, 0);
  EXPECT_EQ(report("w")["subsystems"]["renderer"], true);
  EXPECT_EQ(report("w")["subsystems"]["frame_writer"], true);
  ASSERT_EQ(run("x", "--no-render", "OCTOCUT_EGL_FORCE_FAIL=1").exit_code, 0);
  EXPECT_EQ(report("x")["subsystems"]["renderer"], false);
  EXPECT_EQ(report("x")["subsystems"]["frame_writer"], false);
}

TEST_F(RenderCliTest, AFailureMidRunKeepsTheFramesWrittenSoFar) {
  if (!renderer_available()) GTEST_SKIP() << "built without EGL";
  // A directory squats on frame 2's name: writing it fails, the run fails, frames 0 and 1 stay.
  fs::create_directories(m_dir / "f/frames/frame_000002.png/occupied");
  const CommandResult r = run("f");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  const json rep = report("f");
  EXPECT_EQ(rep["status"], "failed");
  EXPECT_NE(rep["error"].get<std::string>().find("frame_000002.png"), std::string::npos) << rep["error"];
  for (const char* name : {"frame_000000.png", "frame_000001.png"}) {
    const Image image = decode_png(read_file(m_dir / "f/frames" / name), name);
    EXPECT_EQ(image.width, 96) << name;
  }
  EXPECT_FALSE(fs::exists(m_dir / "f/frames/frame_000003.png"));
  for (const auto& e : fs::directory_iterator(m_dir / "f/frames"))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
}

TEST_F(RenderCliTest, EglFailureIsACleanExit2WithTheEglError) {
  const CommandResult r = run("e", "", "OCTOCUT_EGL_FORCE_FAIL=1");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("/render/enabled"), std::string::npos) << r.output;
  if (renderer_available()) {
    EXPECT_NE(r.output.find("EGL_NOT_INITIALIZED (0x3001)"), std::string::npos) << r.output;
  }
  EXPECT_NE(r.output.find("--no-render"), std::string::npos) << r.output;
  const json rep = report("e");
  EXPECT_EQ(rep["status"], "failed");
  EXPECT_FALSE(fs::exists(m_dir / "e/frames"));
}

TEST_F(RenderCliTest, NoEglVendorIsACleanExit2) {
  if (!renderer_available()) GTEST_SKIP() << "built without EGL";
  // libglvnd with no vendor library: no device and no surfaceless platform, a real failure rather than the hook.
  const CommandResult r = run("v", "", "__EGL_VENDOR_LIBRARY_FILENAMES=/nonexistent/vendor.json");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("EGL: no EGL device or surfaceless display could be initialised"), std::string::npos)
      << r.output;
  EXPECT_EQ(report("v")["status"], "failed");
}

TEST_F(RenderCliTest, ABadDeviceIndexIsACleanExit2) {
  if (!renderer_available()) GTEST_SKIP() << "built without EGL";
  const CommandResult r = run("d", "", "OCTOCUT_EGL_DEVICE=99");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("OCTOCUT_EGL_DEVICE=99"), std::string::npos) << r.output;
}

TEST_F(RenderCliTest, NoRenderNeverTouchesEgl) {
  // The forced failure would end the run if EGL were started.
  const CommandResult r = run("x", "--no-render", "OCTOCUT_EGL_FORCE_FAIL=1");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(m_dir / "x/frames"));
  const json rep = report("x");
  EXPECT_EQ(rep["frames"]["rendered"].get<int>(), 0);
  bool warned = false;
  for (const auto& w : rep["warnings"]) warned = warned || w.get<std::string>().find("--no-render") != std::string::npos;
  EXPECT_TRUE(warned);
}

TEST_F(RenderCliTest, RenderKeysAreValidatedWithPointers) {
  const std::string scene = "'" + m_scene.string() + "'";
  const auto check = [&](const std::string& set, const std::string& expected) {
    const CommandResult r = run_octocut("validate " + scene + " --set '" + set + "'");
    EXPECT_EQ(r.exit_code, 2) << set << ": " << r.output;
    EXPECT_NE(r.output.find("cube.json: " + expected), std::string::npos) << set << ": " << r.output;
  };
  check("/render/width=8", "/render/width: must be >= 16, got 8");
  check("/render/every=0", "/render/every: must be >= 1, got 0");
  check("/render/msaa=64", "/render/msaa: must be <= 16, got 64");
  check("/render/camera/fov_deg=180", "/render/camera/fov_deg: must be < 180");
  check("/render/camera/follow_tool=punch", "/render/camera/follow_tool: no tool or prop named \"punch\"");
  check("/render/camera/up=[0,0,0]", "/render/camera/up: must not be zero");
  check("/render/overlays/wireframe=true", "/render/overlays/wireframe: unknown key");
  const CommandResult ok = run_octocut("validate " + scene);
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
}

TEST(RenderBuilder, BoxSurfaceIsClosedWithTheBoxVolumeAndFollowsTheOctree) {
  // A 2 x 1 x 0.5 cm box: each face a grid, outward, enclosing exactly the box's volume.
  const sim::Box3 b{sim::Vec3(0.0, 0.0, 0.0), sim::Vec3(0.02, 0.01, 0.005)};
  const sim::TriMesh mesh = sim::box_face_grids(b, 8);
  // 8 x 4 x 2 cells: faces (x) 4*2, (y) 2*8, (z) 8*4 quads, twice each, two triangles each.
  EXPECT_EQ(mesh.num_triangles(), std::size_t(2 * 2 * (8 + 16 + 32)));
  EXPECT_NEAR(sim::signed_volume(mesh), 0.02 * 0.01 * 0.005, 1e-15);

  // Embedded in an octree over the box and evaluated at the rest slots, every vertex comes back in place.
  sim::OctreeSpec spec;
  spec.root = {sim::Vec3::Zero(), 0.032};
  spec.base_level = 3;
  spec.max_level = 4;
  const sim::ObjectModel model =
      sim::ObjectModel::build(spec, std::make_shared<sim::BoxMaterial>(b), sim::MaterialParams{}, {});
  const EmbeddedSurface surface = embed_surface(model, mesh);
  const RenderMesh rest = tissue_mesh(model, surface, model.slot_rest());
  ASSERT_EQ(rest.positions.size(), mesh.num_vertices());
  for (std::size_t i = 0; i < mesh.num_vertices(); ++i)
    EXPECT_LT((rest.positions[i].cast<double>() - mesh.vertices[i]).norm(), 1e-9) << i;
  // A rigid translation of every slot moves every vertex by the same amount; normals stay unit and outward.
  std::vector<sim::Vec3> moved = model.slot_rest();
  for (sim::Vec3& s : moved) s += sim::Vec3(0.001, -0.002, 0.003);
  const RenderMesh shifted = tissue_mesh(model, surface, moved);
  for (std::size_t i = 0; i < mesh.num_vertices(); ++i) {
    EXPECT_LT((shifted.positions[i].cast<double>() - mesh.vertices[i] - sim::Vec3(0.001, -0.002, 0.003)).norm(), 1e-7);
    EXPECT_NEAR(shifted.normals[i].norm(), 1.0f, 1e-5f);
  }
  // The vertex at the top centre has the normal +z.
  const sim::Vec3 top(0.01, 0.005, 0.005);
  int found = 0;
  for (std::size_t i = 0; i < mesh.num_vertices(); ++i) {
    if ((mesh.vertices[i] - top).norm() < 1e-12) {
      EXPECT_GT(shifted.normals[i].z(), 0.999f);
      ++found;
    }
  }
  EXPECT_EQ(found, 1);
}

TEST(RenderBuilder, DefaultCameraFramesTheObject) {
  const sim::Box3 b{sim::Vec3(-0.01, -0.02, 0.0), sim::Vec3(0.03, 0.02, 0.01)};
  const Camera camera = make_camera(CameraSettings{}, b);
  EXPECT_TRUE(camera.target.isApprox(sim::Vec3(0.01, 0.0, 0.005), 1e-12));
  // Every corner of the bounds projects inside a 1280 x 720 image, in front of the near plane.
  for (int k = 0; k < 8; ++k) {
    const sim::Vec3 c(k & 1 ? b.max.x() : b.min.x(), k & 2 ? b.max.y() : b.min.y(), k & 4 ? b.max.z() : b.min.z());
    const Eigen::Vector3d p = project_to_pixel(camera, 1280, 720, c);
    EXPECT_GT(p.x(), 0.0);
    EXPECT_LT(p.x(), 1280.0);
    EXPECT_GT(p.y(), 0.0);
    EXPECT_LT(p.y(), 720.0);
    EXPECT_GT(p.z(), 0.0);
    EXPECT_LT(p.z(), 1.0);
  }
}

}  // namespace
}  // namespace octocut::engine

namespace octocut::engine {
namespace {

// A closed tetrahedron in mm as OBJ: vertices at the origin and on the three axes (1 cm), outward oriented.
const char* kTetObj = "v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

TEST(PropPose, HeldAtTheEndsLinearPositionSlerpRotation) {
  using Eigen::Vector3d;
  RenderProp prop;
  const Eigen::Matrix4d identity = Eigen::Matrix4d::Identity();
  EXPECT_TRUE(prop_pose(prop, 0.3).isApprox(identity));
  prop.keyframes = {{1.0, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}}, {3.0, {0.02, -0.04, 0.06}, {0.0, 0.0, 90.0}}};
  // Before the first keyframe and after the last: held.
  EXPECT_TRUE(prop_pose(prop, 0.0).isApprox(identity));
  const Eigen::Matrix4d end = prop_pose(prop, 5.0);
  const Eigen::Matrix3d r_end = end.block(0, 0, 3, 3);
  const Vector3d p_end = end.block(0, 3, 3, 1);
  EXPECT_TRUE(p_end.isApprox(Vector3d(0.02, -0.04, 0.06)));
  EXPECT_NEAR((r_end * Vector3d::UnitX() - Vector3d::UnitY()).norm(), 0.0, 1e-12);
  // Halfway: the midpoint, and half the rotation (45 degrees about z).
  const Eigen::Matrix4d mid = prop_pose(prop, 2.0);
  const Eigen::Matrix3d r_mid = mid.block(0, 0, 3, 3);
  const Vector3d p_mid = mid.block(0, 3, 3, 1);
  EXPECT_TRUE(p_mid.isApprox(Vector3d(0.01, -0.02, 0.03)));
  const double c = std::sqrt(0.5);
  EXPECT_NEAR((r_mid * Vector3d::UnitX() - Vector3d(c, c, 0.0)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((r_mid.transpose() * r_mid - Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-12);
  EXPECT_EQ(mid(3, 3), 1.0);
  EXPECT_EQ(mid(3, 0), 0.0);
}

TEST_F(RenderCliTest, PropsAreDrawnAndValidated) {
  std::ofstream(m_dir / "tet.obj") << kTetObj;
  const std::string prop =
      R"(--set '/render/props=[{"name": "tool", "mesh": "tet.obj", "scale": 0.0005, "material": "metal",)"
      R"( "keyframes": [{"t": 0, "position": [0.012, 0.0, 0.004]}, {"t": 0.006, "position": [0.012, 0.004, 0.004]}]}]')";
  // With the prop the frames differ from those without it, and the moving prop changes them over time.
  ASSERT_EQ(run("plain").exit_code, 0);
  const CommandResult r = run("prop", prop);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string f0 = read_file(m_dir / "prop/frames/frame_000000.png");
  EXPECT_NE(f0, read_file(m_dir / "plain/frames/frame_000000.png"));
  EXPECT_NE(read_file(m_dir / "prop/frames/frame_000003.png"), read_file(m_dir / "plain/frames/frame_000003.png"));
  // The camera may follow a prop.
  EXPECT_EQ(run("follow", prop + " --set /render/camera/follow_tool=tool").exit_code, 0);
  EXPECT_NE(read_file(m_dir / "follow/frames/frame_000003.png"), read_file(m_dir / "prop/frames/frame_000003.png"));

  // A missing prop mesh, unsorted keyframes and an open prop mesh are bad input naming the prop's pointer.
  CommandResult bad = run("missing", R"(--set '/render/props=[{"name": "a", "mesh": "nope.obj"}]')");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("/render/props/0/mesh: file not found"), std::string::npos) << bad.output;
  bad = run("unsorted", R"(--set '/render/props=[{"name": "a", "mesh": "tet.obj", "keyframes": [{"t": 1}, {"t": 0.5}]}]')");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("/render/props/0/keyframes/1/t"), std::string::npos) << bad.output;
  std::ofstream(m_dir / "open.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  bad = run("open", R"(--set '/render/props=[{"name": "a", "mesh": "open.obj"}]')");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("/render/props/0/mesh: "), std::string::npos) << bad.output;
  EXPECT_NE(bad.output.find("open.obj"), std::string::npos) << bad.output;
  // validate loads the prop meshes too.
  const CommandResult v = run_octocut("validate '" + m_scene.string() + R"(' --set '/render/props=[{"name": "a", "mesh": "open.obj"}]')");
  EXPECT_EQ(v.exit_code, 2);
  EXPECT_NE(v.output.find("/render/props/0/mesh: "), std::string::npos) << v.output;
  // --no-render never loads the props.
  EXPECT_EQ(run("norender", R"(--no-render --set '/render/props=[{"name": "a", "mesh": "open.obj"}]')").exit_code, 0);
}

}  // namespace
}  // namespace octocut::engine
