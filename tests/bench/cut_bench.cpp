// The object-model side of a cut (SPEC §4 stage 4): ObjectModel::with_material on a 1536-element slab whose
// material graph loses the tets of a small punch or a slit, then the state transfer and the component analysis
// that fragment removal needs. The whole cut must take a few ms, so each of these must stay well below that.
#include <benchmark/benchmark.h>

#include <functional>

#include "../common/kuhn_grid.hpp"
#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/object.hpp"

namespace {

using namespace octocut::sim;

// Tet grid: cubes of edge 1/32 over [0,1] x [0,1] x [0, 3/8] (32 x 32 x 12 cubes, 73,728 tets when full).
constexpr int kNx = 32, kNy = 32, kNz = 12;
constexpr double kCube = 1.0 / 32.0;  // m

std::shared_ptr<MaterialGraph> slab(const std::function<bool(int, int, int)>& keep) {
  return std::make_shared<MaterialGraph>(
      octocut::test::kuhn_grid(Vec3::Zero(), Vec3::Constant(kCube), {kNx, kNy, kNz}, keep));
}

// The uncut slab at level 4 (h = 1/16): 16 x 16 x 6 = 1536 elements, with a handle on its x = 0 end.
const ObjectModel& uncut() {
  static const ObjectModel m = [] {
    OctreeSpec spec;
    spec.root = {Vec3::Zero(), 1.0};
    spec.base_level = 4;
    spec.max_level = 8;
    HandleSpec handle;
    handle.box = {Vec3(-1, -1, -1), Vec3(0.01, 2, 2)};
    return ObjectModel::build(spec, slab([](int, int, int) { return true; }), {}, {handle});
  }();
  return m;
}

// Cut 0: a 2 x 2-cube punch through the slab at its centre (24 leaves touched, no node splits).
// Cut 1: a slit in the plane x = 1/2 for y in [3/8, 5/8] (72 leaves touched; the 3 x 7 nodes inside the slit split,
// its ends y = 3/8 and 5/8 do not).
struct Cut {
  std::shared_ptr<MaterialGraph> material;
  Box3 changed;
};
const Cut& cut(int which) {
  static const Cut punch{slab([](int i, int j, int) { return !((i == 15 || i == 16) && (j == 15 || j == 16)); }),
                         {kCube * Vec3(15, 15, 0), kCube * Vec3(17, 17, kNz)}};
  static const Cut slit{slab([](int i, int j, int) { return !((i == 15 || i == 16) && j >= 12 && j < 20); }),
                        {kCube * Vec3(15, 12, 0), kCube * Vec3(17, 20, kNz)}};
  return which == 0 ? punch : slit;
}

void BM_WithMaterial(benchmark::State& state) {
  const ObjectModel& m = uncut();
  const Cut& c = cut(int(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(m.with_material(c.material, {c.changed}));
  const ObjectModel after = m.with_material(c.material, {c.changed});
  state.counters["elements"] = m.num_elements();
  state.counters["new_dofs"] = after.num_dofs() - m.num_dofs();
}

void BM_GlobalDofBuildForComparison(benchmark::State& state) {
  const ObjectModel& m = uncut();
  const Cut& c = cut(int(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(build_dof_map(m.tree(), m.root(), *c.material));
  state.counters["elements"] = m.num_elements();
}

void BM_TransferState(benchmark::State& state) {
  const ObjectModel& m = uncut();
  const Cut& c = cut(int(state.range(0)));
  const ObjectModel after = m.with_material(c.material, {c.changed});
  const SimState s = SimState::rest(m);
  for (auto _ : state) benchmark::DoNotOptimize(transfer_state(m, s, after));
}

void BM_ComponentsAndInfo(benchmark::State& state) {
  const ObjectModel& m = uncut();
  const Cut& c = cut(int(state.range(0)));
  const ObjectModel after = m.with_material(c.material, {c.changed});
  for (auto _ : state) {
    int count = 0;
    const std::vector<int> comp = element_components(after, count);
    benchmark::DoNotOptimize(component_info(after, comp, count));
  }
}

BENCHMARK(BM_WithMaterial)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_GlobalDofBuildForComparison)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_TransferState)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_ComponentsAndInfo)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
