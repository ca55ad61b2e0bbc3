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

 private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
  int m_threads = 1;
};

}  // namespace octocut::sim
