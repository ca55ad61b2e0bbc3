#pragma once
// Wall-clock timing of the stages that reports list.
#include <chrono>

namespace octocut::sim {

using Clock = std::chrono::steady_clock;

/// Milliseconds elapsed since t0 on the steady clock.
inline double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace octocut::sim
