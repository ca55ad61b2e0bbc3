#pragma once
// A run report without what depends on the machine and its load: the wall time, the real-time factor, the timing
// block and each cut's stage timings and latency. Two runs of the same scene, seed and thread count must agree on
// everything else, bit for bit (the determinism rule).
#include <nlohmann/json.hpp>
#include <string>

namespace octocut::test {

inline std::string report_without_timings(nlohmann::json report) {
  report.erase("timing_ms");
  report.erase("wall_time_s");
  report.erase("realtime_factor");
  if (report.contains("cuts"))
    for (nlohmann::json& c : report["cuts"]) {
      c.erase("ms");
      c.erase("latency_ms");
    }
  return report.dump();
}

}  // namespace octocut::test
