#include "octocut/sim/parallel.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <dlfcn.h>

#include <algorithm>
#include <thread>

namespace octocut::sim {

struct Executor::Impl {
  explicit Impl(int n) : arena(n) {}
  tbb::task_arena arena;
};

Executor::Executor(int threads) {
  m_threads = threads > 0 ? threads : std::max(1, int(std::thread::hardware_concurrency()));
  if (m_threads > 1) m_impl = std::make_unique<Impl>(m_threads);
  // The BLAS behind CHOLMOD runs on one thread between factorisations (see set_blas_threads).
  set_blas_threads(1);
}

void set_blas_threads(int threads) {
  // Looked up at run time, so any BLAS works and none is linked directly.
  using SetThreads = void (*)(int);
  static const auto set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  if (set) set(std::max(1, threads));
}

Executor::~Executor() = default;

void Executor::parallel_for(int n, int grain, const std::function<void(int, int)>& body) {
  if (n <= 0) return;
  // Serial below two grains or with one thread: no scheduling overhead at all.
  if (!m_impl || n < 2 * std::max(1, grain)) {
    body(0, n);
    return;
  }
  m_impl->arena.execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<int>(0, n, std::size_t(std::max(1, grain))),
        [&](const tbb::blocked_range<int>& r) { body(r.begin(), r.end()); }, tbb::static_partitioner());
  });
}

}  // namespace octocut::sim
