// Step time of the issue-2 cube (1 cm, 10 x 10 x 10 leaves, E = 5e4 Pa, nu = 0.45, dt = 1 ms, bottom fixed) per
// linear solver and thread count. `octocut bench step` reports the same case with its error against exact solves.
// Also the product with the implicit Euler matrix that every PCG iteration applies, on that cube refined twice more
// in a corner (hanging nodes and elements of three sizes, as in the meniscus), per thread count.
#include <benchmark/benchmark.h>

#include "octocut/sim/fem_system.hpp"
#include "octocut/sim/parallel.hpp"
#include "octocut/sim/simulator.hpp"

namespace {

using namespace octocut::sim;

ObjectModel cube(std::vector<RefineSpec> refine = {}) {
  OctreeSpec spec;
  spec.root = {Vec3::Zero(), 0.016};
  spec.base_level = 4;
  spec.max_level = 6;
  spec.refine = std::move(refine);
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

// y = (M + dt^2 K) x through FemSystem::system_product, the element matrices applied without assembling them.
void BM_SystemProduct(benchmark::State& state) {
  const ObjectModel m = cube({{Box3{Vec3::Zero(), Vec3::Constant(0.003)}, 6}});
  Executor executor(int(state.range(0)));
  FemSystem fem(m, executor);
  std::vector<Vec3> x;
  for (const Vec3& r : m.dofs().dof_rest) x.push_back(r + 1e-4 * Vec3(r.y(), -r.x(), 0.5 * r.z()) / 0.01);
  ElementFrame frame;
  fem.rotations(x, frame);
  const std::vector<char> constrained(std::size_t(m.num_dofs()), 0);
  const VecX v = VecX::LinSpaced(3 * m.num_dofs(), -1.0, 1.0);
  VecX y;
  for (auto _ : state) {
    fem.system_product(1.0, 1e-6, frame, constrained, v, y);
    benchmark::DoNotOptimize(y.data());
  }
  state.counters["elements"] = m.num_elements();
}
BENCHMARK(BM_SystemProduct)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
