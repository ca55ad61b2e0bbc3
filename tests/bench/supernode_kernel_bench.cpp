// The lagged factor's per-supernode triangular-solve kernels (sim/src/supernode_kernels.hpp), every copy this CPU
// runs (avx512, avx2, generic), forward and backward, on 240 supernodes of 12 shapes from 1 x 20 to 150 x 380 rows
// (11.6 MB of single-precision factor, beyond the caches, as the meniscus's 5 MB factor is beside a step's data).
// docs/RESULTS.md, "AVX2's triangular solves without their sums on the stack", has the figures.
#include <benchmark/benchmark.h>

#include <random>
#include <string>
#include <vector>

#include "supernode_kernels.hpp"

namespace {

using octocut::sim::SupernodeKernelCopy;

struct Supernode {
  int nscol = 0, nsrow = 0, ld = 0;
  std::vector<float> L, diag_inv, scale, w;  // column-major L (ld x nscol), rows padded with zeros as the solves pack
};

const std::vector<Supernode>& supernodes() {
  static const std::vector<Supernode> all = [] {
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    const int shapes[][2] = {{1, 20},    {3, 40},    {4, 60},    {8, 64},    {12, 100},  {16, 128},
                             {24, 150},  {32, 200},  {48, 260},  {64, 300},  {96, 330},  {150, 380}};
    std::vector<Supernode> out;
    for (int rep = 0; rep < 20; ++rep)
      for (const auto& s : shapes) {
        Supernode x;
        x.nscol = s[0];
        x.nsrow = s[1];
        x.ld = (x.nsrow + 15 + 15) / 16 * 16;  // at least nsrow + 15, whole vectors
        x.L.assign(std::size_t(x.ld) * std::size_t(x.nscol), 0.0f);
        for (int j = 0; j < x.nscol; ++j)
          for (int i = j; i < x.nsrow; ++i) x.L[std::size_t(j) * std::size_t(x.ld) + std::size_t(i)] = 0.1f * u(rng);
        for (int j = 0; j < x.nscol; ++j) {
          x.diag_inv.push_back(1.0f + 0.1f * u(rng));
          x.scale.push_back(1.0f);
        }
        x.w.assign(std::size_t(x.ld), 0.0f);
        for (int i = 0; i < x.nsrow; ++i) x.w[std::size_t(i)] = u(rng);
        out.push_back(std::move(x));
      }
    return out;
  }();
  return all;
}

void run(benchmark::State& state, const SupernodeKernelCopy& copy, bool forward) {
  const std::vector<Supernode>& all = supernodes();
  std::vector<std::vector<float>> w;
  for (const Supernode& x : all) w.push_back(x.w);
  for (auto _ : state) {
    for (std::size_t k = 0; k < all.size(); ++k) {
      const Supernode& x = all[k];
      (forward ? copy.forward : copy.backward)(x.L.data(), x.diag_inv.data(), x.scale.data(), x.nscol, x.nsrow, x.ld,
                                               w[k].data());
      w[k] = x.w;  // the same input every pass
    }
    benchmark::ClobberMemory();
  }
}

const int registered = [] {
  for (const SupernodeKernelCopy& copy : octocut::sim::supernode_kernel_copies()) {
    benchmark::RegisterBenchmark((std::string("supernode/forward/") + copy.name).c_str(),
                                 [copy](benchmark::State& s) { run(s, copy, true); })
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark((std::string("supernode/backward/") + copy.name).c_str(),
                                 [copy](benchmark::State& s) { run(s, copy, false); })
        ->Unit(benchmark::kMillisecond);
  }
  return 0;
}();

}  // namespace

BENCHMARK_MAIN();
