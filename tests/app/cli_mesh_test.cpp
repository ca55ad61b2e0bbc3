// `octocut run` with a mesh surface end to end: the mesh is loaded, validated and scaled, M is generated and cached,
// the octree is built on M, and the report states the surface. Bad meshes and parameters exit 2 naming the file and
// the JSON pointer.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "common/cli_util.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "common/temp_dir.hpp"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using octocut::test::CommandResult;
using octocut::test::run_octocut;

// A closed cube of edge 10 mm as OBJ (1-based indices), outward oriented; `flip` reverses every triangle.
std::string cube_obj(bool flip) {
  std::string s;
  for (int k = 0; k < 8; ++k)
    s += "v " + std::to_string(k & 1 ? 10 : 0) + " " + std::to_string(k & 2 ? 10 : 0) + " " +
         std::to_string(k & 4 ? 10 : 0) + "\n";
  const int tris[12][3] = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                           {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  for (const auto& t : tris) {
    const int a = t[0] + 1, b = flip ? t[2] + 1 : t[1] + 1, c = flip ? t[1] + 1 : t[2] + 1;
    s += "f " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(c) + "\n";
  }
  return s;
}

class CliMeshTest : public octocut::test::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    ::setenv("OCTOCUT_CACHE_DIR", (m_dir / "cache").c_str(), 1);
  }
  void TearDown() override {
    ::unsetenv("OCTOCUT_CACHE_DIR");
    TempDirTest::TearDown();
  }
  // A scene on surface file `mesh` (mm), clamped at z < 1.5 mm (the whole bottom layer of leaves: root 10.5 mm at
  // level 3 puts the first node layer above z = 0 at 1.06 mm).
  fs::path scene(const std::string& mesh, const std::string& cell_size = "0.002") {
    return write("scene.json", R"({
      "name": "mesh cube", "duration": 0.02,
      "solver": {"dt": 0.001, "threads": 2},
      "object": {"surface": ")" + mesh + R"(", "scale": 0.001,
                 "material": {"young_modulus": 5e4, "poisson_ratio": 0.45},
                 "material_graph": {"cell_size": )" + cell_size + R"(},
                 "octree": {"base_level": 3},
                 "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 0.0015]}}]},
      "probes": [{"name": "top", "point": [0.005, 0.005, 0.0099]}]
    })");
  }
  json report() {
    std::ifstream in(m_dir / "out" / "report.json");
    return json::parse(in);
  }
  CommandResult run(const fs::path& scene_file) {
    return run_octocut("run '" + scene_file.string() + "' --out '" + (m_dir / "out").string() + "' --quiet");
  }
};

TEST_F(CliMeshTest, MeshSurfaceRunsEndToEndAndTheCacheIsUsed) {
  write("cube.obj", cube_obj(false));
  const CommandResult r = run(scene("cube.obj"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = report();
  EXPECT_EQ(j["status"], "ok");
  EXPECT_EQ(j["counts"]["surface_vertices"], 8);
  EXPECT_EQ(j["counts"]["surface_triangles"], 12);
  EXPECT_GT(j["counts"]["tets"].get<int>(), 20);
  EXPECT_GT(j["counts"]["elements"].get<int>(), 8);
  EXPECT_EQ(j["surface"]["closed"], true);
  EXPECT_EQ(j["surface"]["self_intersecting"], false);
  EXPECT_EQ(j["surface"]["components"], 1);
  // 10 mm cube, scaled to metres: exactly 1e-6 m^3 by the divergence theorem.
  EXPECT_NEAR(j["surface"]["rest_volume_m3"].get<double>(), 1e-6, 1e-18);
  // Clamped at the bottom, the top sags under gravity.
  const double dz = j["probes"]["top"]["displacement"][2].get<double>();
  EXPECT_LT(dz, 0.0);
  EXPECT_GT(dz, -1e-3);
  // The run wrote one cache entry; a second run reads it and reports the same numbers.
  int entries = 0;
  for (const auto& e : fs::recursive_directory_iterator(m_dir / "cache")) entries += e.is_regular_file();
  EXPECT_EQ(entries, 1);
  const json first = j;
  ASSERT_EQ(run(scene("cube.obj")).exit_code, 0);
  const json second = report();
  EXPECT_EQ(first["counts"], second["counts"]);
  EXPECT_EQ(first["probes"], second["probes"]);
}

TEST_F(CliMeshTest, SurfaceOutputsAreTheRestAndDeformedSurfaces) {
  write("cube.obj", cube_obj(false));
  const fs::path s = scene("cube.obj");
  const CommandResult r = run_octocut("run '" + s.string() + "' --out '" + (m_dir / "out").string() +
                                      "' --quiet --set /output/surface_final=true --set /output/surface_every=10");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const fs::path out = m_dir / "out";
  EXPECT_TRUE(fs::exists(out / "surfaces" / "surface_000010.ply"));
  EXPECT_TRUE(fs::exists(out / "surfaces" / "surface_000020.ply"));
  EXPECT_FALSE(fs::exists(out / "surfaces" / "surface_000005.ply"));
  // The rest surface is the input in metres (float32 in the file).
  const octocut::sim::TriMesh rest = octocut::engine::load_mesh(out / "surface_rest.ply").mesh;
  const octocut::sim::TriMesh final_surface = octocut::engine::load_mesh(out / "surface_final.ply").mesh;
  ASSERT_EQ(rest.num_vertices(), 8u);
  ASSERT_EQ(final_surface.num_vertices(), 8u);
  EXPECT_NEAR(octocut::sim::signed_volume(rest), 1e-6, 1e-12);
  for (std::size_t v = 0; v < 8; ++v) {
    const auto& p = rest.vertices[v];
    const auto& q = final_surface.vertices[v];
    if (p.z() < 1e-9) {
      // The clamped bottom does not move.
      EXPECT_NEAR((q - p).norm(), 0.0, 1e-9) << v;
    } else {
      // The free top sags under gravity, by less than a millimetre.
      EXPECT_LT(q.z(), p.z()) << v;
      EXPECT_GT(q.z(), p.z() - 1e-3) << v;
    }
  }
}

TEST_F(CliMeshTest, ShippedMeniscusRestSceneRunsFinite) {
  // The shipped scene, shortened: the 10k meniscus held at both horns sags under gravity and stays finite.
  const std::string scene_file = std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/meniscus_rest.json";
  const CommandResult r = run_octocut("run '" + scene_file + "' --out '" + (m_dir / "out").string() +
                                      "' --quiet --set /duration=0.1 --set /output/surface_final=false");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json j = report();
  EXPECT_EQ(j["status"], "ok");
  EXPECT_EQ(j["stability"]["finite"], true);
  EXPECT_EQ(j["counts"]["surface_vertices"], 10022);
  EXPECT_EQ(j["counts"]["surface_triangles"], 20040);
  EXPECT_GT(j["counts"]["tets"].get<int>(), 5000);
  EXPECT_GT(j["counts"]["elements"].get<int>(), 1000);
  EXPECT_EQ(j["surface"]["closed"], true);
  EXPECT_EQ(j["surface"]["self_intersecting"], false);
  EXPECT_EQ(j["surface"]["components"], 1);
  // The generator's volume of meniscus_10k.ply: 2513.679 mm^3.
  EXPECT_NEAR(j["surface"]["rest_volume_m3"].get<double>(), 2.513679e-6, 1e-12);
  // Held only at the horns, the body sags; less at the inner rim than at the periphery, which is further from the
  // horns' line.
  const double periphery = j["probes"]["body_periphery"]["displacement"][2].get<double>();
  const double rim = j["probes"]["inner_rim"]["displacement"][2].get<double>();
  EXPECT_LT(periphery, 0.0);
  EXPECT_LT(rim, 0.0);
  EXPECT_LT(periphery, rim);
}

TEST_F(CliMeshTest, InvertedMeshIsReorientedWithAWarning) {
  write("inverted.obj", cube_obj(true));
  ASSERT_EQ(run(scene("inverted.obj")).exit_code, 0);
  const json j = report();
  EXPECT_NEAR(j["surface"]["rest_volume_m3"].get<double>(), 1e-6, 1e-18);
  bool warned = false;
  for (const auto& w : j["warnings"]) {
    const std::string text = w.get<std::string>();
    if (text.find("reoriented") == std::string::npos) continue;
    warned = true;
    // It names where (the pointer) and the file, once.
    EXPECT_EQ(text.rfind("/object/surface: ", 0), 0u) << text;
    const std::size_t named = text.find("inverted.obj");
    ASSERT_NE(named, std::string::npos) << text;
    EXPECT_EQ(text.find("inverted.obj", named + 1), std::string::npos) << text;
  }
  EXPECT_TRUE(warned) << j["warnings"].dump();
}

TEST_F(CliMeshTest, BadMeshesAndParametersAreBadInput) {
  // Missing file.
  CommandResult r = run(scene("missing.obj"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("/object/surface"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("missing.obj"), std::string::npos) << r.output;
  // An open mesh: the cube without its last triangle.
  std::string open = cube_obj(false);
  open.erase(open.rfind("f "));
  write("open.obj", open);
  r = run(scene("open.obj"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("/object/surface"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("open.obj"), std::string::npos) << r.output;
  // A cell size that would ask for billions of tets.
  write("cube.obj", cube_obj(false));
  r = run(scene("cube.obj", "1e-6"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("/object/material_graph/cell_size"), std::string::npos) << r.output;
  // Nothing was run, so no report.
  EXPECT_FALSE(fs::exists(m_dir / "out" / "report.json"));
}

}  // namespace
