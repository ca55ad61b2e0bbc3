// The per-step surface update (SPEC §2.4): deformed positions and normals of a 50k-vertex surface embedded in a
// 4096-leaf model, on 1 and 2 threads. Requirement: positions of 50k vertices within 1 ms per step on 2 cores.
#include <benchmark/benchmark.h>

#include <cmath>
#include <numbers>

#include "octocut/sim/embedding.hpp"
#include "octocut/sim/surface.hpp"
#include "../common/shapes.hpp"

namespace {

using namespace octocut::sim;

// The shared procedural ellipsoid.
TriMesh ellipsoid(const Vec3& centre, const Vec3& radii, int segments, int rings) {
  return octocut::test::ellipsoid_mesh(centre, radii, segments, rings);
}

// A 14 mm box of material in a 16 mm root, 1 mm leaves (4096 elements), and a 50002-vertex ellipsoid inside it.
struct Fixture {
  ObjectModel model;
  TriMesh surface;
  SurfaceEmbedding embedding;
  std::vector<Vec3> x;  ///< deformed DOF positions, m (num_dofs)
};

const Fixture& fixture() {
  static const Fixture f = [] {
    OctreeSpec spec;
    spec.root = {Vec3::Zero(), 0.016};
    spec.base_level = 4;
    spec.max_level = 8;
    ObjectModel m = ObjectModel::build(
        spec, std::make_shared<BoxMaterial>(Box3{Vec3::Constant(0.001), Vec3::Constant(0.015)}), {}, {});
    TriMesh s = ellipsoid(Vec3::Constant(0.008), Vec3(0.0065, 0.006, 0.0055), 250, 201);
    SurfaceEmbedding e(m, s.vertices, s.triangles);
    std::vector<Vec3> x;
    for (const Vec3& X : m.dofs().dof_rest)
      x.push_back(X + 0.0005 * Vec3(std::sin(400 * X.y()), std::cos(300 * X.z()), std::sin(500 * X.x())));
    return Fixture{std::move(m), std::move(s), std::move(e), std::move(x)};
  }();
  return f;
}

void BM_DeformedPositions50k(benchmark::State& state) {
  const Fixture& f = fixture();
  Executor exec(int(state.range(0)));
  std::vector<Vec3> p;
  for (auto _ : state) {
    f.embedding.deformed_positions(f.x, p, exec);
    benchmark::DoNotOptimize(p.data());
  }
  state.counters["vertices"] = f.embedding.num_vertices();
  state.counters["entries_per_vertex"] = double(f.embedding.dof_index().size()) / f.embedding.num_vertices();
}

void BM_DeformedNormals50k(benchmark::State& state) {
  const Fixture& f = fixture();
  Executor exec(int(state.range(0)));
  std::vector<Vec3> p, n, faces;
  f.embedding.deformed_positions(f.x, p, exec);
  for (auto _ : state) {
    f.embedding.deformed_normals(p, n, exec, faces);
    benchmark::DoNotOptimize(n.data());
  }
  state.counters["vertices"] = f.embedding.num_vertices();
}

void BM_EmbeddingBuild50k(benchmark::State& state) {
  const Fixture& f = fixture();
  for (auto _ : state) {
    SurfaceEmbedding e(f.model, f.surface.vertices, f.surface.triangles);
    benchmark::DoNotOptimize(e.dof_index().data());
  }
}

// The full SurfaceEmbedding::update of a cut on a 10k-vertex surface: 2 mm ball of vertices removed, 100 inserted
// inside it, the model unchanged (uniform trees of level 4, 5, 6). Includes the leaf matching (linear in the leaves)
// and the recomposition of every vertex through P (linear in the vertices).
void BM_SurfaceUpdateCut10k(benchmark::State& state) {
  OctreeSpec spec;
  spec.root = {Vec3::Zero(), 0.016};
  spec.base_level = int(state.range(0));
  spec.max_level = 8;
  const ObjectModel m = ObjectModel::build(
      spec, std::make_shared<BoxMaterial>(Box3{Vec3::Constant(0.001), Vec3::Constant(0.015)}), {}, {});
  const TriMesh s = ellipsoid(Vec3::Constant(0.008), Vec3(0.0065, 0.006, 0.0055), 128, 79);
  const SurfaceEmbedding start(m, s.vertices, s.triangles);
  // The cut: vertices near the +x point of the equator go, 100 points on the ball's inner cap come; kept triangles
  // survive.
  const Vec3 spot = s.vertices[1 + 39 * 128];
  SurfaceEdit edit;
  std::vector<int> map(s.vertices.size(), -1);
  int next = 0;
  for (std::size_t v = 0; v < s.vertices.size(); ++v) {
    if ((s.vertices[v] - spot).norm() < 0.002)
      edit.removed_vertices.push_back(int(v));
    else
      map[v] = next++;
  }
  for (int i = 0; i < 100; ++i) {
    const double c = 1.0 - 0.5 * (i + 0.5) / 100, sn = std::sqrt(1.0 - c * c), ph = 2.39996323 * i;
    edit.inserted_rest.push_back(spot + 0.002 * Vec3(-c, sn * std::cos(ph), sn * std::sin(ph)));
  }
  for (const auto& t : s.triangles)
    if (map[std::size_t(t[0])] >= 0 && map[std::size_t(t[1])] >= 0 && map[std::size_t(t[2])] >= 0)
      edit.triangles.push_back({map[std::size_t(t[0])], map[std::size_t(t[1])], map[std::size_t(t[2])]});
  for (auto _ : state) {
    state.PauseTiming();
    SurfaceEmbedding e = start;
    state.ResumeTiming();
    benchmark::DoNotOptimize(e.update(m, edit));
  }
  state.counters["leaves"] = m.num_elements();
  state.counters["vertices"] = start.num_vertices();
  state.counters["removed"] = double(edit.removed_vertices.size());
}

BENCHMARK(BM_DeformedPositions50k)->ArgName("threads")->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_DeformedNormals50k)->ArgName("threads")->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_EmbeddingBuild50k)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SurfaceUpdateCut10k)->ArgName("level")->Arg(4)->Arg(5)->Arg(6)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
