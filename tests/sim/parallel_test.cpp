// Executor's two ways of sharing a loop: every index exactly once, whatever the thread count.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <vector>

#include "octocut/sim/parallel.hpp"

namespace octocut::sim {
namespace {

// Counts the visits of every index of [0, n) and the largest range handed to the body.
struct Visits {
  explicit Visits(int n) : count(static_cast<std::size_t>(n)) {}
  std::vector<std::atomic<int>> count;
  std::atomic<int> widest{0};
  void operator()(int b, int e) {
    int w = widest.load();
    while (e - b > w && !widest.compare_exchange_weak(w, e - b)) {
    }
    for (int k = b; k < e; ++k) ++count[static_cast<std::size_t>(k)];
  }
  [[nodiscard]] bool once() const {
    for (const auto& c : count)
      if (c.load() != 1) return false;
    return true;
  }
};

TEST(Executor, ParallelForEachHandsOutEveryItemOnceAndOneAtATimeOnTwoThreads) {
  for (const int threads : {1, 2}) {
    Executor executor(threads);
    for (const int n : {0, 1, 2, 7, 1000}) {
      Visits v(n);
      executor.parallel_for_each(n, [&](int b, int e) { v(b, e); });
      EXPECT_TRUE(v.once()) << threads << " threads, n = " << n;
      // One thread runs the whole range at once; two hand out single items.
      if (threads == 2 && n >= 2) {
        EXPECT_EQ(v.widest.load(), 1) << "n = " << n;
      }
    }
  }
}

TEST(Executor, ParallelForCoversTheRangeOnce) {
  for (const int threads : {1, 2}) {
    Executor executor(threads);
    for (const int n : {0, 1, 5, 64, 1001}) {
      Visits v(n);
      executor.parallel_for(n, 4, [&](int b, int e) { v(b, e); });
      EXPECT_TRUE(v.once()) << threads << " threads, n = " << n;
    }
  }
}

// Per-index results of a loop whose items cost very different amounts are the same on one and two threads.
TEST(Executor, ParallelForEachGivesTheSameResultsOnOneAndTwoThreads) {
  constexpr int kItems = 64;
  std::vector<double> out[2];
  for (const int threads : {1, 2}) {
    Executor executor(threads);
    std::vector<double>& o = out[threads - 1];
    o.assign(kItems, 0.0);
    executor.parallel_for_each(kItems, [&](int b, int e) {
      for (int k = b; k < e; ++k) {
        double s = 0.0;  // item k sums 1/i over i < 1000 (k + 1): items 64 times apart in cost
        for (int i = 1; i < 1000 * (k + 1); ++i) s += 1.0 / i;
        o[static_cast<std::size_t>(k)] = s;
      }
    });
  }
  EXPECT_EQ(out[0], out[1]);
  // Item 0 is the harmonic number H_999 = ln 999 + gamma + 1/1998 - 1/(12 999^2) + O(999^-4).
  EXPECT_NEAR(out[0][0], std::log(999.0) + 0.5772156649015329 + 1.0 / 1998.0 - 1.0 / (12.0 * 999.0 * 999.0), 1e-10);
}

}  // namespace
}  // namespace octocut::sim
