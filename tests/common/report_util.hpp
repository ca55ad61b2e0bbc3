#pragma once
// Reading the JSON files a run writes (report, session, study), and a run report without what depends on the
// machine and its load.
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

namespace octocut::test {

/// The JSON document in a file; throws nlohmann::json::parse_error when it is missing or malformed.
inline nlohmann::json read_json(const std::filesystem::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

/// The report without the wall time, the real-time factor, the timing block, each cut's stage timings and latency,
/// and where the material graph came from (`subsystems.material_graph`: "meshed" by the first run on a machine,
/// "cache" by the next ones, which read the same M from the disk cache). Two runs of the same scene, seed and thread
/// count must agree on everything else, bit for bit (the determinism rule).
inline std::string report_without_timings(nlohmann::json report) {
  report.erase("timing_ms");
  report.erase("wall_time_s");
  report.erase("realtime_factor");
  if (report.contains("subsystems") && report["subsystems"].is_object()) report["subsystems"].erase("material_graph");
  if (report.contains("cuts"))
    for (nlohmann::json& c : report["cuts"]) {
      c.erase("ms");
      c.erase("latency_ms");
      c.erase("bridge_ms");
      c.erase("settle_max_ms");
    }
  return report.dump();
}

}  // namespace octocut::test
