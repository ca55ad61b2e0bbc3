// Step time of the issue-2 cube (1 cm, 10 x 10 x 10 leaves, E = 5e4 Pa, nu = 0.45, dt = 1 ms, bottom fixed) per
// linear solver and thread count. `octocut bench step` reports the same case with its error against exact solves.
#include <benchmark/benchmark.h>

#include "octocut/sim/simulator.hpp"

namespace {

using namespace octocut::sim;

ObjectModel cube() {
  OctreeSpec spec;
  spec.root = {Vec3::Zero(), 0.016};
  spec.base_level = 4;
  MaterialParams p;
  p.young_modulus = 5e4;
  p.poisson_ratio = 0.45;
  HandleSpec bottom{{Vec3(-1, -1, -1), Vec3(1, 1, 1e-9)}, {}};
  return ObjectModel::build(spec, std::make_shared<BoxMaterial>(Box3{Vec3::Zero(), Vec3::Constant(0.01)}), p,
                            {bottom});
}

void run(benchmark::State& state, const char* solver, const char* pre) {
  SimulatorOptions o;
  o.linear_solver = solver;
  o.preconditioner = pre;
  o.tolerance = 1e-3;
  o.threads = int(state.range(0));
  Simulator sim(cube(), o);
  for (int i = 0; i < 10; ++i) sim.step();  // symbolic analysis and first factorisation
  for (auto _ : state) sim.step();
  state.counters["dofs"] = sim.model().num_dofs();
}

void BM_StepPcgCholesky(benchmark::State& s) { run(s, "pcg", "cholesky"); }
void BM_StepPcgJacobi(benchmark::State& s) { run(s, "pcg", "jacobi"); }
void BM_StepCholmod(benchmark::State& s) { run(s, "cholmod", "cholesky"); }

BENCHMARK(BM_StepPcgCholesky)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_StepPcgJacobi)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_StepCholmod)->Arg(2)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
