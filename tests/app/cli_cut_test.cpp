// `octocut cut` (SPEC §7): one rest-space cut, its octocut.cut/1 report, and bad blades that write nothing.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>

#include "common/shapes.hpp"
#include "common/cli_util.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/sim/surface_check.hpp"
#include "common/temp_dir.hpp"

namespace octocut {
namespace {

namespace fs = std::filesystem;
using sim::Vec3;

sim::TriMesh prism(const Vec3& c, double r, double h, int n) { return test::prism_mesh(c, r, h, n); }

struct CutCli : test::TempDirTest {
  const fs::path& dir = m_dir;
  void SetUp() override {
    TempDirTest::SetUp();
    // A 20 mm cube in millimetres, gridded, and a 2 mm-radius, 32-gon punch through it.
    engine::save_mesh(dir / "cube.off", sim::closed_box_grid({Vec3(0, 0, 0), Vec3(20, 20, 20)}, 10));
    engine::save_mesh(dir / "punch.off", prism(Vec3(10, 10, 10), 2.0, 30.0, 32));
  }
  std::string p(const std::string& name) const { return "'" + (m_dir / name).string() + "'"; }
  nlohmann::json report(const std::string& name) const {
    std::ifstream in(m_dir / name);
    return nlohmann::json::parse(in);
  }
};

TEST_F(CutCli, PunchThroughACubeReportsTheExactVolume) {
  const auto r = test::run_octocut("cut --surface " + p("cube.off") + " --blade " + p("punch.off") + " --out " +
                                   p("out.off") + " --scale 0.001 --report " + p("cut.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json j = report("cut.json");
  EXPECT_EQ(j["schema"], "octocut.cut/1");
  EXPECT_EQ(j["status"], "ok");
  // Mesh files are read through assimp in single precision: the exact answer is the area of the blade's ring as
  // loaded (shoelace) times the cube's height.
  const sim::TriMesh blade = engine::load_mesh(dir / "punch.off", {0.001, true, false}).mesh;
  std::vector<Vec3> ring;  // the bottom ring, by angle about the axis
  for (const Vec3& v : blade.vertices)
    if (v.z() < 0.0 && std::hypot(v.x() - 0.01, v.y() - 0.01) > 1e-3) ring.push_back(v);
  ASSERT_EQ(ring.size(), 32u);
  std::sort(ring.begin(), ring.end(), [](const Vec3& a, const Vec3& b) {
    return std::atan2(a.y() - 0.01, a.x() - 0.01) < std::atan2(b.y() - 0.01, b.x() - 0.01);
  });
  double area = 0.0;  // m^2
  for (std::size_t i = 0; i < ring.size(); ++i) {
    const Vec3& a = ring[i];
    const Vec3& b = ring[(i + 1) % ring.size()];
    area += 0.5 * (a.x() * b.y() - a.y() * b.x());
  }
  const double removed = area * 0.02;  // m^3
  EXPECT_NEAR(j["removed_volume_m3"].get<double>(), removed, 1e-9 * removed);
  EXPECT_NEAR(j["input_volume_m3"].get<double>(), 8e-6, 1e-18);
  EXPECT_NEAR(j["output_volume_m3"].get<double>(), 8e-6 - removed, 1e-9 * 8e-6);
  EXPECT_EQ(j["closed"], true);
  EXPECT_EQ(j["self_intersecting"], false);
  EXPECT_EQ(j["components"], 1);
  EXPECT_EQ(j["blade_perturbed"], 0);  // a generic position: the blade was used as it is
  EXPECT_GT(j["material_graph"]["tets_removed"].get<int>(), 0);
  for (const char* k : {"surface", "material_graph", "total"}) EXPECT_GE(j["ms"][k].get<double>(), 0.0) << k;
  // The output is in metres, closed, and has the reported volume (to single precision, as read back).
  const sim::TriMesh out = engine::load_mesh(dir / "out.off", {1.0, true, true}).mesh;
  EXPECT_NEAR(sim::signed_volume(out), 8e-6 - removed, 1e-6 * 8e-6);
  EXPECT_EQ(long(out.num_vertices()), j["output_vertices"].get<long>());
}

TEST_F(CutCli, BladeThatMissesIsANoOp) {
  engine::save_mesh(dir / "far.off", prism(Vec3(50, 50, 50), 2.0, 5.0, 16));
  const auto r = test::run_octocut("cut --surface " + p("cube.off") + " --blade " + p("far.off") + " --out " +
                                   p("out.off") + " --scale 0.001 --report " + p("cut.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(report("cut.json")["status"], "no-op");
  EXPECT_DOUBLE_EQ(report("cut.json")["removed_volume_m3"].get<double>(), 0.0);
  EXPECT_TRUE(fs::exists(dir / "out.off"));
}

TEST_F(CutCli, BadBladesExitTwoAndWriteNothing) {
  // Open: one triangle missing.
  sim::TriMesh open = prism(Vec3(10, 10, 10), 2.0, 30.0, 16);
  open.triangles.pop_back();
  std::ofstream(dir / "open.obj") << [&] {
    std::string s;
    for (const Vec3& v : open.vertices) s += "v " + std::to_string(v.x()) + " " + std::to_string(v.y()) + " " + std::to_string(v.z()) + "\n";
    for (const auto& t : open.triangles)
      s += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " + std::to_string(t[2] + 1) + "\n";
    return s;
  }();
  // NaN coordinates.
  std::ofstream(dir / "nan.obj") << "v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n";
  // Self-intersecting: two overlapping closed prisms in one file.
  sim::TriMesh twice = prism(Vec3(10, 10, 10), 2.0, 30.0, 16);
  const sim::TriMesh other = prism(Vec3(11, 10, 10), 2.0, 30.0, 16);
  const int off = int(twice.vertices.size());
  twice.vertices.insert(twice.vertices.end(), other.vertices.begin(), other.vertices.end());
  for (auto t : other.triangles) twice.triangles.push_back({t[0] + off, t[1] + off, t[2] + off});
  engine::save_mesh(dir / "twice.ply", twice);
  for (const char* bad : {"open.obj", "nan.obj", "twice.ply"}) {
    const auto r = test::run_octocut("cut --surface " + p("cube.off") + " --blade " + p(bad) + " --out " +
                                     p("out.off") + " --report " + p("cut.json"));
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find(bad), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(dir / "out.off")) << bad;
    EXPECT_FALSE(fs::exists(dir / "cut.json")) << bad;
  }
}

}  // namespace
}  // namespace octocut

namespace octocut {
namespace {

// A cut result written as PLY reads back as the same surface, bit for bit: its volume, summed over the same triangles
// in the same order from the coordinates read back, equals the report's output volume exactly (JSON numbers are
// written with round-trip precision). Float PLY (--ply-float) does not. OBJ coordinates are round-trip decimals.
TEST_F(CutCli, CutResultsReadBackBitForBit) {
  for (const char* out : {"out.ply", "out_float.ply", "out.obj"}) {
    const std::string flags = std::string(out) == "out_float.ply" ? " --ply-float" : "";
    const auto r = test::run_octocut("cut --surface " + p("cube.off") + " --blade " + p("punch.off") + " --out " +
                                     p(out) + " --scale 0.001 --report " + p("cut.json") + flags);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const nlohmann::json j = report("cut.json");
  const double volume = j["output_volume_m3"].get<double>();
  const sim::TriMesh exact = engine::load_mesh(dir / "out.ply").mesh;
  EXPECT_EQ(long(exact.num_vertices()), j["output_vertices"].get<long>());
  EXPECT_EQ(long(exact.num_triangles()), j["output_triangles"].get<long>());
  EXPECT_EQ(sim::signed_volume(exact), volume);
  const sim::TriMesh single = engine::load_mesh(dir / "out_float.ply").mesh;
  EXPECT_EQ(single.num_triangles(), exact.num_triangles());
  EXPECT_NE(sim::signed_volume(single), volume);
  EXPECT_NEAR(sim::signed_volume(single), volume, 1e-6 * volume);
  // The OBJ's "v" lines parse to exactly the PLY's vertices (as sorted sets of points).
  std::ifstream obj(dir / "out.obj");
  std::vector<std::array<double, 3>> from_obj, from_ply;
  for (std::string line; std::getline(obj, line);) {
    if (line.rfind("v ", 0) != 0) continue;
    std::array<double, 3> v{};
    char* end = line.data() + 2;
    for (double& c : v) c = std::strtod(end, &end);
    from_obj.push_back(v);
  }
  for (const Vec3& v : exact.vertices) from_ply.push_back({v.x(), v.y(), v.z()});
  std::sort(from_obj.begin(), from_obj.end());
  std::sort(from_ply.begin(), from_ply.end());
  EXPECT_EQ(from_obj, from_ply);
}

}  // namespace
}  // namespace octocut
