// Stage 2 of the cut pipeline (SPEC §4): the local surface boolean S \ B' for a 2 mm-diameter cylinder punch
// (assets/meshes/blade_cyl2mm.ply) partially into the inner rim of the 10k and 50k meniscus (scaled to metres).
// Requirement: the median time at 50k is at most 1.5x that at 10k (the CGAL part must not grow with |S|), a few ms.
#include <benchmark/benchmark.h>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "octocut/cutting/surface_cut.hpp"
#include "octocut/engine/io/mesh_io.hpp"

namespace {

using namespace octocut;

sim::TriMesh load(const std::string& name) {
  engine::MeshLoadOptions o;
  o.scale = 0.001;
  o.self_intersections = false;
  return engine::load_mesh(std::string(OCTOCUT_SOURCE_DIR) + "/assets/meshes/" + name, o).mesh;
}

// The blade (z in [-6, 6] mm, axis z) centred on the inner rim point for psi = 270 deg, (0, -6) mm, and lifted so
// that its bottom cap is 0.5 mm above the meniscus' flat bottom: it enters from the top and stops inside.
const sim::TriMesh& blade() {
  static const sim::TriMesh b = [] {
    sim::TriMesh m = load("blade_cyl2mm.ply");
    const double psi = 270.0 * std::numbers::pi / 180.0;
    const sim::Vec3 shift(0.01275 * std::cos(psi), 0.006 * std::sin(psi), 0.0065);
    for (sim::Vec3& p : m.vertices) p += shift;
    return m;
  }();
  return b;
}

// `one` with four translated copies of itself 0.1 m away.
sim::TriMesh padded(const sim::TriMesh& one) {
  sim::TriMesh m = one;
  for (int k = 1; k <= 4; ++k) {
    const auto offset = static_cast<int32_t>(m.vertices.size());
    for (const sim::Vec3& p : one.vertices) m.vertices.push_back(p + sim::Vec3(0.1 * k, 0.0, 0.0));
    for (const auto& t : one.triangles) m.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  }
  return m;
}

void run(benchmark::State& state, const sim::TriMesh& surface) {
  const sim::TriMesh& b = blade();
  cutting::SurfaceCutResult r;
  for (auto _ : state) {
    r = cutting::cut_surface(surface, b);
    if (r.status != cutting::SurfaceCutStatus::ok) {
      state.SkipWithError(("cut failed: " + r.reason).c_str());
      return;
    }
    benchmark::DoNotOptimize(r.mesh.triangles.data());
  }
  state.counters["surface_triangles"] = static_cast<double>(surface.triangles.size());
  state.counters["patch_triangles"] = r.patch_triangles;
  state.counters["removed_mm3"] = r.removed_volume * 1e9;
}

// The pipeline's form: S edited in place through its grid (built once, outside the timing), the edit rolled back
// after each iteration (not timed).
void run_in_place(benchmark::State& state, const sim::TriMesh& s) {
  sim::TriMesh mesh = s;
  cutting::FaceGrid grid;
  grid.build(mesh);
  std::vector<char> cut(mesh.triangles.size(), 0);
  cutting::SurfaceEditor editor(mesh, grid, &cut);
  const sim::TriMesh& b = blade();
  cutting::SurfaceEditResult r;
  for (auto _ : state) {
    r = cutting::cut_surface_in_place(editor, b);
    if (r.status != cutting::SurfaceCutStatus::ok) {
      state.SkipWithError(("cut failed: " + r.reason).c_str());
      return;
    }
    state.PauseTiming();
    editor.rollback(0);
    state.ResumeTiming();
  }
  state.counters["surface_triangles"] = static_cast<double>(s.triangles.size());
  state.counters["patch_triangles"] = r.patch_triangles;
}

void BM_SurfaceCut_Meniscus10k(benchmark::State& state) {
  static const sim::TriMesh s = load("meniscus_10k.ply");
  run(state, s);
}
void BM_SurfaceCut_Meniscus50k(benchmark::State& state) {
  static const sim::TriMesh s = load("meniscus_50k.ply");
  run(state, s);
}
// The 10k meniscus with four translated copies of itself 0.1 m away: |S| as at 50k (50k vertices), the patch exactly
// as at 10k. The difference to BM_SurfaceCut_Meniscus10k is the part of the cut that grows with |S|; the difference
// between BM_SurfaceCut_Meniscus50k and this one is the growth of the local work with the mesh resolution.
void BM_SurfaceCut_Meniscus10kPadded(benchmark::State& state) {
  static const sim::TriMesh s = padded(load("meniscus_10k.ply"));
  run(state, s);
}
void BM_SurfaceCutInPlace_Meniscus10k(benchmark::State& state) { run_in_place(state, load("meniscus_10k.ply")); }
void BM_SurfaceCutInPlace_Meniscus10kPadded(benchmark::State& state) {
  const sim::TriMesh one = load("meniscus_10k.ply");
  run_in_place(state, padded(one));
}
void BM_SurfaceCutInPlace_Meniscus50k(benchmark::State& state) { run_in_place(state, load("meniscus_50k.ply")); }
// The grid over S that the pipeline builds once per object (cutting::index_surface), at 50k vertices.
void BM_FaceGrid_Build50k(benchmark::State& state) {
  static const sim::TriMesh s = load("meniscus_50k.ply");
  for (auto _ : state) {
    cutting::FaceGrid grid;
    grid.build(s);
    benchmark::DoNotOptimize(grid.dims());
  }
}
void BM_SurfaceCut_Meniscus50kNoVerify(benchmark::State& state) {
  static const sim::TriMesh s = load("meniscus_50k.ply");
  const sim::TriMesh& b = blade();
  cutting::SurfaceCutOptions o;
  o.verify = false;
  for (auto _ : state) {
    const cutting::SurfaceCutResult r = cutting::cut_surface(s, b, o);
    benchmark::DoNotOptimize(r.mesh.triangles.data());
  }
}

BENCHMARK(BM_SurfaceCut_Meniscus10k)->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true);
BENCHMARK(BM_SurfaceCut_Meniscus10kPadded)->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true);
BENCHMARK(BM_SurfaceCut_Meniscus50k)->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true);
BENCHMARK(BM_SurfaceCutInPlace_Meniscus10k)->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true);
BENCHMARK(BM_SurfaceCutInPlace_Meniscus10kPadded)->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true);
BENCHMARK(BM_SurfaceCutInPlace_Meniscus50k)->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true);
BENCHMARK(BM_FaceGrid_Build50k)->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true);
BENCHMARK(BM_SurfaceCut_Meniscus50kNoVerify)->Unit(benchmark::kMillisecond)->Repetitions(5)->ReportAggregatesOnly(true);

}  // namespace

BENCHMARK_MAIN();
