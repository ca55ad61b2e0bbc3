// DOF map construction: the global build against the local update after refining one leaf (SPEC §2.3), on uniform
// trees of 4k, 33k and 262k leaves.
#include <benchmark/benchmark.h>

#include "octocut/sim/object.hpp"

namespace {

using namespace octocut::sim;

ObjectModel block(int level) {
  OctreeSpec spec;
  spec.root = {Vec3::Zero(), 1.0};
  spec.base_level = level;
  spec.max_level = level + 4;
  return ObjectModel::build(spec, std::make_shared<BoxMaterial>(Box3{Vec3::Constant(0.01), Vec3::Constant(0.99)}),
                            {}, {});
}

void BM_DofMapGlobalBuild(benchmark::State& state) {
  const ObjectModel m = block(int(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(build_dof_map(m.tree(), m.root(), m.material()));
  state.counters["leaves"] = m.num_elements();
}

void BM_RefineOneLeafLocalUpdate(benchmark::State& state) {
  const ObjectModel m = block(int(state.range(0)));
  int leaf = 0;
  for (auto _ : state) benchmark::DoNotOptimize(m.refined({leaf++ % m.num_elements()}));
  state.counters["leaves"] = m.num_elements();
}

BENCHMARK(BM_DofMapGlobalBuild)->Arg(4)->Arg(5)->Arg(6)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RefineOneLeafLocalUpdate)->Arg(4)->Arg(5)->Arg(6)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
