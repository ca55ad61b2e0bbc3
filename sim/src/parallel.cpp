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

void serial_openmp_here() {
  using SetInt = void (*)(int);
  struct Setters {
    SetInt dynamic, num_threads, max_active_levels;
  };
  static const Setters set{reinterpret_cast<SetInt>(dlsym(RTLD_DEFAULT, "omp_set_dynamic")),
                           reinterpret_cast<SetInt>(dlsym(RTLD_DEFAULT, "omp_set_num_threads")),
                           reinterpret_cast<SetInt>(dlsym(RTLD_DEFAULT, "omp_set_max_active_levels"))};
  // No active level allowed: every region gets one thread at once. Dynamic adjustment with one thread as the
  // nthreads-var bounds a num_threads clause too, in case this libgomp keeps the levels process-wide.
  if (set.max_active_levels) set.max_active_levels(0);
  if (set.dynamic) set.dynamic(1);
  if (set.num_threads) set.num_threads(1);
}

Executor::~Executor() = default;

namespace {

// body over [0, n) in the arena, in TBB ranges of at least `grain` items split as `partitioner` says; serial below
// two grains or without an arena (one thread): no scheduling overhead at all.
template <class Partitioner>
void run_loop(tbb::task_arena* arena, int n, int grain, const std::function<void(int, int)>& body,
              Partitioner partitioner) {
  if (n <= 0) return;
  grain = std::max(1, grain);
  if (arena == nullptr || n < 2 * grain) {
    body(0, n);
    return;
  }
  arena->execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<int>(0, n, std::size_t(grain)),
        [&](const tbb::blocked_range<int>& r) { body(r.begin(), r.end()); }, partitioner);
  });
}

}  // namespace

void Executor::parallel_for(int n, int grain, const std::function<void(int, int)>& body) {
  run_loop(m_impl ? &m_impl->arena : nullptr, n, grain, body, tbb::static_partitioner());
}

void Executor::parallel_for_each(int n, const std::function<void(int, int)>& body) {
  run_loop(m_impl ? &m_impl->arena : nullptr, n, 1, body, tbb::simple_partitioner());
}

}  // namespace octocut::sim
