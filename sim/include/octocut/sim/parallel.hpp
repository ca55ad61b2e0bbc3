#pragma once
// Thread control for element loops: a fixed-size arena so that `solver.threads` is respected and nothing
// oversubscribes. Workers sleep when idle (TBB), so a busy second core does not slow the loop down by spinning.
#include <functional>
#include <memory>

namespace octocut::sim {

class Executor {
 public:
  /// threads = 0 picks the hardware concurrency.
  explicit Executor(int threads);
  ~Executor();
  [[nodiscard]] int threads() const { return m_threads; }
  /// Calls body(begin, end) over disjoint chunks covering [0, n), in parallel. Each index is visited once; results
  /// written per index are deterministic whatever the thread count.
  void parallel_for(int n, int grain, const std::function<void(int, int)>& body);
  /// The same for items whose costs differ widely (contact queries: a sample beside a tool costs tens of
  /// microseconds, one far from it nothing): with more than one thread, body(k, k + 1) for each item, handed out one
  /// at a time to whichever thread is free, instead of in one equal share per thread; with one, body(0, n).
  void parallel_for_each(int n, const std::function<void(int, int)>& body);

 private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
  int m_threads = 1;
};

/// Sets the thread count of the BLAS behind CHOLMOD (OpenBLAS on Debian, found at run time; a no-op for other BLAS).
/// OpenBLAS's idle workers spin with sched_yield after every call that used them, burning a core that the step, the
/// frame writer or the renderer could use, so octocut keeps the BLAS at one thread (Executor's constructor sets it):
/// raising it around numeric factorisations gained nothing measurable, even at 34k DOFs, and cost a core of spinning
/// (docs/RESULTS.md, "CHOLMOD's OpenMP teams run serially").
void set_blas_threads(int threads);

/// Makes the OpenMP parallel regions that the calling thread starts run on that thread alone (libgomp found at run
/// time; a no-op without it). Debian's CHOLMOD runs parts of its supernodal numeric factorisation in OpenMP teams of
/// a fixed 4 threads (CHOLMOD_OMP_NUM_THREADS, a num_threads clause that omp_set_num_threads cannot lower): on two
/// cores those teams spin at their barriers against the simulation step, and against each other when a background
/// factorisation runs beside the step. The limits are per thread in libgomp (dynamic adjustment, one thread, no
/// active levels), so every thread that factorises calls this first. Factorisations then run on one core each, the
/// BLAS included (set_blas_threads), and the other core stays with the step.
void serial_openmp_here();

}  // namespace octocut::sim
