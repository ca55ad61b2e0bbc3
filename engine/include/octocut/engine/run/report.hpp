#pragma once
// The run report (SPEC §8), as plain data, and its JSON text (schema octocut.report/1).
#include <array>
#include <string>
#include <vector>

namespace octocut::engine {

/// This build's version (the project's VERSION), written into every report as `octocut_version`.
const char* version();

/// Median, 95th percentile and maximum of a list of durations, ms.
struct TimingSummary {
  double median = 0.0, p95 = 0.0, max = 0.0;
  static TimingSummary of(std::vector<double> samples_ms);
};

/// Names of the timed parts of a cut in CutSummary::ms: the stages of SPEC §4, then the total.
inline constexpr std::array<const char*, 8> kCutStageKeys = {
    "back_transform", "surface", "material_graph", "refine", "node_split", "embedding", "solver_update", "total"};

/// One cut event of a run (the report's `cuts[]`, SPEC §8).
struct CutSummary {
  double t = 0.0;                  ///< time of the cut, s
  std::string tool;                ///< the tool's name
  std::string status;              ///< "ok" | "skipped" | "no-op"
  std::string reason;              ///< why skipped or no-op; empty when ok
  bool scheduled = true;           ///< on the scene's timeline (false: World::cut_now)
  int components = 0;              ///< material components the blade touched
  int restricted_components = 0;   ///< of those, the ones whose rest-space blade left other material alone
  int unrestricted_components = 0; ///< of those, the ones whose restriction could not close up and was dropped
  double removed_volume_m3 = 0.0;  ///< V(S) - V(S') of the boolean, m^3
  int tets_removed = 0;            ///< tets of M removed
  int leaves_refined = 0;          ///< refine operations
  int fragments_removed = 0;       ///< loose pieces removed
  double fragment_volume_m3 = 0.0; ///< their material volume, m^3
  int snapped = 0;                 ///< rest-space blades snapped onto a recent cut's within cutting.min_feature
  int collapses = 0;               ///< edits of the rounding repair (edge collapses, cap flips, bubbles removed)
  int new_triangles = 0;           ///< triangles the surface boolean made
  double min_angle_deg = 0.0;      ///< smallest angle among them, degrees (reported null when there are none)
  double min_edge_m = 0.0;         ///< shortest edge among them, m (reported null when there are none)
  long elements_after = 0, dofs_after = 0, surface_vertices_after = 0;
  std::array<double, 8> ms{};      ///< per kCutStageKeys, ms
  /// What the user waits for: the cut's total plus the first simulation step after it, ms (the cut alone when the
  /// run ends before another step).
  double latency_ms = 0.0;
  /// The first step's bridge solve, which the cut's model thread prepared while the surface stage still ran, ms (0
  /// when it did not): work of that step done ahead of it, outside ms's solver_update (CutStageMs::bridge).
  double bridge_ms = 0.0;
  /// The longest simulation step (contact, step, surface update; no cut) among the kSettleSteps steps after the cut,
  /// fewer when the run ends first, ms: whether the cut stalls the steps that follow it (the solver's bridge and
  /// its background factorisation).
  double settle_max_ms = 0.0;
  static constexpr int kSettleSteps = 10;
};

struct ProbeResult {
  std::string name;
  std::array<double, 3> rest{};          ///< m
  std::array<double, 3> displacement{};  ///< m
};

/// What a run built (the report's `subsystems`): each part is built only when the scene uses it.
struct Subsystems {
  bool renderer = false;                 ///< a GL renderer was started (render.enabled, no --no-render)
  bool frame_writer = false;             ///< frames were written (output.frames with a renderer)
  bool cut_index = false;                ///< the face grid over S that cuts use (a tool cut, or has cut events)
  bool contact = false;                  ///< a Bullet contact world (something collides or there are rigid bodies)
  std::string material_graph = "box";    ///< "box" | "cache" | "meshed": where M came from
};

/// A colliding tool in the report's `contact.tools`.
struct ToolContactSummary {
  std::string name;
  double max_force_n = 0.0;              ///< largest |force| the tissue exerted on it in any step, N
  std::array<double, 3> final_force_n{}; ///< the force in the last step, N (3)
};

/// A rigid body in the report's `contact.bodies`, at the end of the run.
struct BodyContactSummary {
  std::string name;
  std::array<double, 3> position{};      ///< body frame origin, m (3)
  std::array<double, 3> rotation_deg{};  ///< XYZ Euler angles, degrees (3)
  std::array<double, 3> velocity_m_s{};  ///< linear velocity (dynamic bodies; 0 otherwise), m/s (3)
  std::array<double, 3> force_n{};       ///< the force the tissue exerts on it in the last step, N (3)
};

/// The report's `contact` block (null when the scene built no contact world).
struct ContactSummary {
  bool present = false;
  double max_penetration_m = 0.0;  ///< deepest collision sample at the start of any step, m
  long samples = 0;                ///< collision samples on S now
  double stiffness_pa_m = 0.0;     ///< the penalty used, Pa/m
  std::vector<ToolContactSummary> tools;
  std::vector<BodyContactSummary> bodies;
};

/// Stability tracked every step (scene `output.stability_track`; the report's `stability.track`, absent when off).
struct StabilityTrack {
  bool enabled = false;
  long energy_steps = 0;            ///< steps with no handle motion and no cut, over which the energy was compared
  /// largest rise over one such step of E = kinetic + elastic + gravitational, plus the contacts' penalty energy
  /// change, minus the work the rigid shapes did on the tissue through contact in it, J
  double energy_rise_j = 0.0;
  double contact_work_j = 0.0;      ///< work the rigid shapes did on the tissue through contact over the run, J
  double energy_scale_j = 0.0;      ///< largest kinetic + elastic + |gravitational| seen, J (the scale of the rise)
  double max_displacement_m = 0.0;  ///< largest |x - X| over the DOFs and the steps, m
  double volume_change = 0.0;       ///< deformed material volume / rest volume - 1 after the last step
  double min_volume_change = 0.0;   ///< smallest of it over the steps
  double max_volume_change = 0.0;   ///< largest of it over the steps
};

struct Report {
  std::string status = "ok";  ///< "ok" | "failed"
  std::string error;
  std::string scene;
  std::string name;
  long steps = 0;
  double sim_time_s = 0.0;
  double wall_time_s = 0.0;
  /// Simulated time over the wall time of the stepping loop (steps, cuts and, in a run, frames and surface files;
  /// not the loading before the first step). 1 or more keeps up with the clock; 0 when no step ran.
  double realtime_factor = 0.0;
  TimingSummary step_ms, render_ms, frame_write_ms;
  /// Per frame: World::render_scene() on the simulation thread (the snapshot the render thread draws), and the time
  /// the simulation waited for room in the render thread's queue, ms (zero summaries when nothing rendered).
  TimingSummary snapshot_ms, render_wait_ms;
  long frames_rendered = 0;  ///< frames the renderer drew
  long frames = 0;           ///< frames written to frames/ (PNG)
  long elements = 0, dofs = 0, hanging_slots = 0, tets = 0, surface_vertices = 0, surface_triangles = 0;
  Subsystems subsystems;
  std::vector<CutSummary> cuts;
  std::vector<ProbeResult> probes;
  ContactSummary contact;
  bool finite = true;
  long recoveries = 0, failed_steps = 0, solver_failures = 0, nonfinite = 0, speed_limit = 0, newton_unconverged = 0;
  long energy_rejections = 0;  ///< step attempts the energy guard rolled back (solver.energy_guard)
  long energy_projections = 0;     ///< accepted attempts whose energy gain was taken out (sim::StabilityStats)
  long energy_shortened = 0;       ///< of those, attempts shortened first
  double energy_removed_j = 0.0;   ///< J, the energy gains those took out
  double energy_unremoved_j = 0.0; ///< J, gains larger than the kinetic energy left in place
  double max_speed_m_s = 0.0;
  double min_volume_ratio = 1.0;  ///< smallest element det F seen at the start of a step (dimensionless)
  double kinetic_j = 0.0, elastic_j = 0.0;
  StabilityTrack track;  ///< output.stability_track
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
