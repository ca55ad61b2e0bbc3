#pragma once
// The run report (SPEC §8), as plain data, and its JSON text (schema octocut.report/1).
#include <array>
#include <string>
#include <vector>

#include "octocut/engine/world.hpp"

namespace octocut::engine {

/// Median, 95th percentile and maximum of a list of durations, ms.
struct TimingSummary {
  double median = 0.0, p95 = 0.0, max = 0.0;
  static TimingSummary of(std::vector<double> samples_ms);
};

struct ProbeResult {
  std::string name;
  std::array<double, 3> rest{};          ///< m
  std::array<double, 3> displacement{};  ///< m
};

struct Report {
  std::string status = "ok";  ///< "ok" | "failed"
  std::string error;
  std::string scene;
  std::string name;
  long steps = 0;
  double sim_time_s = 0.0;
  double wall_time_s = 0.0;
  TimingSummary step_ms, render_ms, frame_write_ms;
  long frames_rendered = 0;  ///< frames the renderer drew
  long frames = 0;           ///< frames written to frames/ (PNG)
  long elements = 0, dofs = 0, hanging_slots = 0, tets = 0, surface_vertices = 0, surface_triangles = 0;
  std::vector<CutSummary> cuts;
  std::vector<ProbeResult> probes;
  bool finite = true;
  long recoveries = 0, failed_steps = 0, solver_failures = 0, nonfinite = 0, speed_limit = 0, newton_unconverged = 0;
  double max_speed_m_s = 0.0;
  double kinetic_j = 0.0, elastic_j = 0.0;
  bool surface_closed = true, surface_self_intersecting = false;
  double rest_volume_m3 = 0.0;
  long surface_components = 0;
  long surface_genus = 0;      ///< sum over the components of S of their genus (through-holes)
  bool object_removed = false; ///< every element was cut away
  std::vector<std::string> warnings;
};

/// The report as pretty-printed JSON; numbers are written with round-trip precision, so equal runs give equal text.
std::string report_json(const Report& report);

}  // namespace octocut::engine
