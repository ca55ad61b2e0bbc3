// The per-step surface update (SPEC §2.4): deformed positions and normals of a 50k-vertex surface embedded in a
// 4096-leaf model, on 1 and 2 threads. Requirement: positions of 50k vertices within 1 ms per step on 2 cores.
#include <benchmark/benchmark.h>

#include <array>
#include <cmath>
#include <numbers>
#include <optional>
#include <utility>

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
    SurfaceEmbedding e(m, s);
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
    f.embedding.deformed_normals(f.surface, p, n, exec, faces);
    benchmark::DoNotOptimize(n.data());
  }
  state.counters["vertices"] = f.embedding.num_vertices();
}

void BM_EmbeddingBuild50k(benchmark::State& state) {
  const Fixture& f = fixture();
  for (auto _ : state) {
    SurfaceEmbedding e(f.model, f.surface);
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
  const SurfaceEmbedding start(m, s);
  // The cut: vertices near the +x point of the equator go, 100 points on the ball's inner cap come; kept triangles
  // survive. `after` is S after the cut.
  const Vec3 spot = s.vertices[1 + 39 * 128];
  SurfaceEdit edit;
  TriMesh after;
  std::vector<int> map(s.vertices.size(), -1);
  int next = 0;
  for (std::size_t v = 0; v < s.vertices.size(); ++v) {
    if ((s.vertices[v] - spot).norm() < 0.002) {
      edit.removed_vertices.push_back(int(v));
    } else {
      map[v] = next++;
      after.vertices.push_back(s.vertices[v]);
    }
  }
  for (int i = 0; i < 100; ++i) {
    const double c = 1.0 - 0.5 * (i + 0.5) / 100, sn = std::sqrt(1.0 - c * c), ph = 2.39996323 * i;
    after.vertices.push_back(spot + 0.002 * Vec3(-c, sn * std::cos(ph), sn * std::sin(ph)));
  }
  edit.inserted = 100;
  for (const auto& t : s.triangles)
    if (map[std::size_t(t[0])] >= 0 && map[std::size_t(t[1])] >= 0 && map[std::size_t(t[2])] >= 0)
      after.triangles.push_back({map[std::size_t(t[0])], map[std::size_t(t[1])], map[std::size_t(t[2])]});
  for (auto _ : state) {
    state.PauseTiming();
    SurfaceEmbedding e = start;
    state.ResumeTiming();
    benchmark::DoNotOptimize(e.update(m, after, edit));
  }
  state.counters["leaves"] = m.num_elements();
  state.counters["vertices"] = start.num_vertices();
  state.counters["removed"] = double(edit.removed_vertices.size());
}

// A cut-like edit of the 50002-vertex fixture: the 11 x 11 quads of the (ring, segment) grid around a spot near the
// +x end of the equator lose their 100 inner vertices; each inner vertex comes back pushed 0.3 mm inwards and each
// quad gets a centre vertex (221 inserted), every quad split into 4 triangles around its centre, so the surface
// stays closed and consistently oriented. The model is refined one level on the leaves that meet the patch (its
// new DOFs renumber those after them) and the new leaves there are listed as changed.
struct Cut50k {
  ObjectModel model;
  SurfaceEdit edit;
  TriMesh surface;  ///< S after the cut
};

const Cut50k& cut50k() {
  static const Cut50k c = [] {
    const Fixture& f = fixture();
    constexpr int kSegments = 250, kI0 = 95, kI1 = 106, kJ0 = 2, kJ1 = 13;  // rings kI0..kI1, segments kJ0..kJ1
    auto ring = [](int i, int j) { return 1 + (i - 1) * kSegments + j; };
    const int nv = int(f.surface.vertices.size());
    const Vec3 centre = Vec3::Constant(0.008);
    auto pushed = [&](const Vec3& p) { return Vec3(p - 0.0003 * (p - centre).normalized()); };
    SurfaceEdit edit;
    TriMesh after;
    std::vector<Vec3> inserted;
    std::vector<int> map(std::size_t(nv), 0);
    for (int i = kI0 + 1; i < kI1; ++i)
      for (int j = kJ0 + 1; j < kJ1; ++j) {
        edit.removed_vertices.push_back(ring(i, j));
        map[std::size_t(ring(i, j))] = -1;
      }
    int next = 0;
    for (int& m : map) m = m < 0 ? -1 : next++;
    // New indices: the inner vertices (row-major), then the quad centres.
    auto inner = [&](int i, int j) { return next + (i - kI0 - 1) * (kJ1 - kJ0 - 1) + (j - kJ0 - 1); };
    for (int i = kI0 + 1; i < kI1; ++i)
      for (int j = kJ0 + 1; j < kJ1; ++j)
        inserted.push_back(pushed(f.surface.vertices[std::size_t(ring(i, j))]));
    auto vertex = [&](int i, int j) {
      return map[std::size_t(ring(i, j))] >= 0 ? map[std::size_t(ring(i, j))] : inner(i, j);
    };
    auto position = [&](int i, int j) {
      const int v = vertex(i, j);
      return v >= next ? inserted[std::size_t(v - next)] : f.surface.vertices[std::size_t(ring(i, j))];
    };
    for (const auto& t : f.surface.triangles)
      if (map[std::size_t(t[0])] >= 0 && map[std::size_t(t[1])] >= 0 && map[std::size_t(t[2])] >= 0)
        after.triangles.push_back({map[std::size_t(t[0])], map[std::size_t(t[1])], map[std::size_t(t[2])]});
    for (int i = kI0; i < kI1; ++i)
      for (int j = kJ0; j < kJ1; ++j) {
        // Quad a b c d in the fixture's orientation (triangles a b c and a c d), split around its centre m.
        const int a = vertex(i, j), b = vertex(i + 1, j), cc = vertex(i + 1, j + 1), d = vertex(i, j + 1);
        const int m = next + int(inserted.size());
        inserted.push_back(
            pushed(0.25 * (position(i, j) + position(i + 1, j) + position(i + 1, j + 1) + position(i, j + 1))));
        for (const auto& t : {std::array<int32_t, 3>{a, b, m}, {b, cc, m}, {cc, d, m}, {d, a, m}})
          after.triangles.push_back(t);
      }
    // Refine the leaves that meet the patch's box (grown by 0.2 mm) by one level; the new leaves there change.
    Box3 patch{Vec3::Constant(1.0), Vec3::Constant(-1.0)};
    for (int i = kI0; i <= kI1; ++i)
      for (int j = kJ0; j <= kJ1; ++j) {
        patch.min = patch.min.cwiseMin(f.surface.vertices[std::size_t(ring(i, j))]);
        patch.max = patch.max.cwiseMax(f.surface.vertices[std::size_t(ring(i, j))]);
      }
    patch.min -= Vec3::Constant(0.0002);
    patch.max += Vec3::Constant(0.0002);
    const RootGeometry& root = f.model.root();
    const int base = f.model.tree().leaf(0).level;
    ObjectModel refined = f.model.refined_where(
        [&](const Cell& c) { return c.level == base && root.cell_box(c).overlap_volume(patch) > 0.0; });
    for (int l = 0; l < refined.num_elements(); ++l)
      if (root.cell_box(refined.tree().leaf(l)).overlap_volume(patch) > 0.0) edit.changed_leaves.push_back(l);
    // S after the cut: the kept vertices in order, then the inserted ones.
    for (int v = 0; v < nv; ++v)
      if (map[std::size_t(v)] >= 0) after.vertices.push_back(f.surface.vertices[std::size_t(v)]);
    after.vertices.insert(after.vertices.end(), inserted.begin(), inserted.end());
    edit.inserted = int(inserted.size());
    return Cut50k{std::move(refined), std::move(edit), std::move(after)};
  }();
  return c;
}

// SurfaceEmbedding::update for the cut above on the 50k fixture; the copy of the embedding is not timed. fresh_copy 0:
// the copy is assigned into one long-lived embedding, so its buffers are warm as in the simulation loop; 1: a freshly
// constructed copy each time (cold pages, no spare capacity). Requirement: at most 1.5 ms per cut.
void BM_SurfaceUpdateCut50k(benchmark::State& state) {
  const Fixture& f = fixture();
  const Cut50k& c = cut50k();
  const bool fresh = state.range(0) != 0;
  SurfaceEmbedding e = f.embedding;
  std::optional<SurfaceEmbedding> copy;
  for (auto _ : state) {
    state.PauseTiming();
    if (fresh) {
      copy.reset();
      copy.emplace(f.embedding);
    } else {
      e = f.embedding;
    }
    state.ResumeTiming();
    benchmark::DoNotOptimize((fresh ? *copy : e).update(c.model, c.surface, c.edit));
  }
  state.counters["vertices"] = f.embedding.num_vertices();
  state.counters["removed"] = double(c.edit.removed_vertices.size());
  state.counters["inserted"] = double(c.edit.inserted);
  state.counters["leaves_before"] = f.model.num_elements();
  state.counters["leaves_after"] = c.model.num_elements();
  state.counters["changed_leaves"] = double(c.edit.changed_leaves.size());
  state.counters["dofs_after"] = c.model.num_dofs();
  state.counters["reembedded"] = e.last_reembedded();
}

BENCHMARK(BM_DeformedPositions50k)->ArgName("threads")->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_DeformedNormals50k)->ArgName("threads")->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_EmbeddingBuild50k)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SurfaceUpdateCut10k)->ArgName("level")->Arg(4)->Arg(5)->Arg(6)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SurfaceUpdateCut50k)
    ->ArgName("fresh_copy")
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
