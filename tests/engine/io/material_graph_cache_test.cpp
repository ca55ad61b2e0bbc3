// The material graph from CGAL Mesh_3 and its disk cache: volume against the surface, conservation of occupancy,
// determinism, and detection of corrupted, truncated and stale cache entries.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>

#include "octocut/cutting/material_mesher.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/io/material_graph_cache.hpp"
#include "octocut/sim/material_graph.hpp"
#include "common/temp_dir.hpp"

namespace octocut::engine {
namespace {

using sim::Vec3;

// An icosphere of radius r (m), outward oriented, by `levels` rounds of 4-to-1 subdivision.
sim::TriMesh icosphere(double r, int levels) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  sim::TriMesh m;
  m.vertices = {Vec3(-1, t, 0), Vec3(1, t, 0), Vec3(-1, -t, 0), Vec3(1, -t, 0), Vec3(0, -1, t), Vec3(0, 1, t),
                Vec3(0, -1, -t), Vec3(0, 1, -t), Vec3(t, 0, -1), Vec3(t, 0, 1), Vec3(-t, 0, -1), Vec3(-t, 0, 1)};
  m.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                 {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                 {3, 8, 9},  {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.vertices.push_back(0.5 * (m.vertices[std::size_t(a)] + m.vertices[std::size_t(b)]));
      return mid[key] = int(m.vertices.size() - 1);
    };
    std::vector<std::array<int32_t, 3>> next;
    for (const auto& f : m.triangles) {
      const int a = midpoint(f[0], f[1]), b = midpoint(f[1], f[2]), c = midpoint(f[2], f[0]);
      next.push_back({f[0], a, c});
      next.push_back({f[1], b, a});
      next.push_back({f[2], c, b});
      next.push_back({a, b, c});
    }
    m.triangles = std::move(next);
  }
  for (Vec3& p : m.vertices) p = r * p.normalized();
  return m;
}

bool same_mesh(const sim::TetMesh& a, const sim::TetMesh& b) {
  return a.vertices == b.vertices && a.tets == b.tets;
}

// A private cache folder per test, removed at the end.
class CacheTest : public octocut::test::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    ::setenv("OCTOCUT_CACHE_DIR", m_dir.c_str(), 1);
  }
  void TearDown() override {
    ::unsetenv("OCTOCUT_CACHE_DIR");
    TempDirTest::TearDown();
  }
};

TEST(MaterialMesher, SphereVolumeAndOccupancyConservation) {
  const sim::TriMesh sphere = icosphere(0.01, 3);
  const sim::TetMesh tets = cutting::mesh_interior(sphere, 0.002);
  const sim::MaterialGraph g(tets);
  // M approximates the polyhedral sphere: volume within 3 % (facet distance is a tenth of the cell size).
  const double v_surface = sim::signed_volume(sphere);
  EXPECT_NEAR(g.volume(), v_surface, 0.03 * v_surface);
  EXPECT_GT(g.num_tets(), 100);
  // Occupancy times cell volume over every cell of a uniform grid sums to the tet volume.
  const double size = 0.024, h = size / 8;
  double sum = 0.0;
  for (int k = 0; k < 8; ++k)
    for (int j = 0; j < 8; ++j)
      for (int i = 0; i < 8; ++i) {
        const Vec3 lo = Vec3::Constant(-0.012) + h * Vec3(i, j, k);
        const sim::Box3 cell{lo, lo + Vec3::Constant(h)};
        sum += g.occupancy(cell) * cell.volume();
      }
  EXPECT_NEAR(sum, g.volume(), 1e-12 * g.volume());
}

TEST(MaterialMesher, IsDeterministicAndRejectsBadInput) {
  const sim::TriMesh sphere = icosphere(0.01, 2);
  EXPECT_TRUE(same_mesh(cutting::mesh_interior(sphere, 0.003), cutting::mesh_interior(sphere, 0.003)));
  EXPECT_THROW(cutting::mesh_interior(sphere, 0.0), cutting::MeshingError);
  EXPECT_THROW(cutting::mesh_interior(sim::TriMesh{}, 0.001), cutting::MeshingError);
}

TEST_F(CacheTest, SecondCallReadsTheEntry) {
  const sim::TriMesh sphere = icosphere(0.01, 2);
  const MaterialGraphResult a = material_graph_for(sphere, 0.003);
  EXPECT_FALSE(a.from_cache);
  EXPECT_TRUE(a.warning.empty()) << a.warning;
  EXPECT_TRUE(std::filesystem::is_regular_file(a.entry));
  EXPECT_EQ(a.entry.parent_path().parent_path(), m_dir);
  const MaterialGraphResult b = material_graph_for(sphere, 0.003);
  EXPECT_TRUE(b.from_cache);
  EXPECT_TRUE(same_mesh(a.mesh, b.mesh));
  // Another cell size or another surface is another entry.
  EXPECT_NE(material_graph_key(sphere, 0.003), material_graph_key(sphere, 0.0031));
  sim::TriMesh moved = sphere;
  moved.vertices[0].x() += 1e-9;
  EXPECT_NE(material_graph_key(sphere, 0.003), material_graph_key(moved, 0.003));
}

TEST_F(CacheTest, CorruptedOrTruncatedEntriesAreRebuilt) {
  const sim::TriMesh sphere = icosphere(0.01, 2);
  const MaterialGraphResult fresh = material_graph_for(sphere, 0.003);
  const std::string good = read_file(fresh.entry);

  // One flipped byte in the payload.
  std::string bad = good;
  bad[bad.size() / 2] = char(bad[bad.size() / 2] ^ 0x5a);
  write_file_atomic(fresh.entry, bad);
  MaterialGraphResult r = material_graph_for(sphere, 0.003);
  EXPECT_FALSE(r.from_cache);
  EXPECT_NE(r.warning.find("checksum"), std::string::npos) << r.warning;
  EXPECT_TRUE(same_mesh(r.mesh, fresh.mesh));
  EXPECT_EQ(read_file(fresh.entry), good);  // the rebuilt entry replaced the bad one

  // Truncated, and empty.
  for (std::size_t keep : {good.size() - 100, std::size_t(10), std::size_t(0)}) {
    write_file_atomic(fresh.entry, good.substr(0, keep));
    r = material_graph_for(sphere, 0.003);
    EXPECT_FALSE(r.from_cache) << keep;
    EXPECT_FALSE(r.warning.empty()) << keep;
    EXPECT_TRUE(same_mesh(r.mesh, fresh.mesh)) << keep;
  }
  // Now valid again.
  EXPECT_TRUE(material_graph_for(sphere, 0.003).from_cache);
}

TEST_F(CacheTest, AnEntryForOtherContentUnderThisKeyIsStale) {
  const sim::TriMesh a = icosphere(0.01, 2), b = icosphere(0.008, 2);
  const MaterialGraphResult ra = material_graph_for(a, 0.003);
  const MaterialGraphResult rb = material_graph_for(b, 0.003);
  // Put b's (valid, checksummed) entry where a's belongs: the key inside it does not match.
  std::filesystem::copy_file(rb.entry, ra.entry, std::filesystem::copy_options::overwrite_existing);
  const MaterialGraphResult r = material_graph_for(a, 0.003);
  EXPECT_FALSE(r.from_cache);
  EXPECT_NE(r.warning.find("other content"), std::string::npos) << r.warning;
  EXPECT_TRUE(same_mesh(r.mesh, ra.mesh));
}

}  // namespace
}  // namespace octocut::engine
