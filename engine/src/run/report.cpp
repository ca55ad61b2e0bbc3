#include "octocut/engine/run/report.hpp"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "octocut/version.hpp"

namespace octocut::engine {

const char* version() { return kVersion; }

TimingSummary TimingSummary::of(std::vector<double> s) {
  TimingSummary t;
  if (s.empty()) return t;
  std::sort(s.begin(), s.end());
  auto at = [&](double q) { return s[std::min(s.size() - 1, std::size_t(std::floor(q * double(s.size() - 1) + 0.5)))]; };
  t.median = at(0.5);
  t.p95 = at(0.95);
  t.max = s.back();
  return t;
}

namespace {
using ojson = nlohmann::ordered_json;
ojson timing(const TimingSummary& t) { return {{"median", t.median}, {"p95", t.p95}, {"max", t.max}}; }
// JSON has no NaN or infinity: non-finite numbers are written as null.
ojson num(double v) { return std::isfinite(v) ? ojson(v) : ojson(nullptr); }
ojson vec(const std::array<double, 3>& v) { return ojson::array({num(v[0]), num(v[1]), num(v[2])}); }
}  // namespace

std::string report_json(const Report& r) {
  nlohmann::ordered_json j;
  j["schema"] = "octocut.report/1";
  j["octocut_version"] = version();
  j["status"] = r.status;
  j["error"] = r.error.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(r.error);
  j["scene"] = r.scene;
  j["name"] = r.name;
  j["steps"] = r.steps;
  j["sim_time_s"] = num(r.sim_time_s);
  j["wall_time_s"] = r.wall_time_s;
  j["realtime_factor"] = r.realtime_factor;
  j["timing_ms"] = {{"step", timing(r.step_ms)},         {"render", timing(r.render_ms)},
                    {"frame_write", timing(r.frame_write_ms)}, {"snapshot", timing(r.snapshot_ms)},
                    {"render_wait", timing(r.render_wait_ms)}};
  j["frames"] = {{"rendered", r.frames_rendered}, {"written", r.frames}};
  j["counts"] = {{"elements", r.elements},         {"dofs", r.dofs},
                 {"hanging_slots", r.hanging_slots}, {"tets", r.tets},
                 {"surface_vertices", r.surface_vertices}, {"surface_triangles", r.surface_triangles}};
  j["subsystems"] = {{"renderer", r.subsystems.renderer},
                     {"frame_writer", r.subsystems.frame_writer},
                     {"cut_index", r.subsystems.cut_index},
                     {"contact", r.subsystems.contact},
                     {"material_graph", r.subsystems.material_graph}};
  j["cuts"] = nlohmann::ordered_json::array();
  for (const CutSummary& c : r.cuts) {
    ojson ms = ojson::object();
    for (std::size_t k = 0; k < c.ms.size(); ++k) ms[std::string(kCutStageKeys[k])] = c.ms[k];
    j["cuts"].push_back({{"t", c.t},
                         {"tool", c.tool},
                         {"status", c.status},
                         {"scheduled", c.scheduled},
                         {"reason", c.reason.empty() ? ojson(nullptr) : ojson(c.reason)},
                         {"components", c.components},
                         {"restricted_components", c.restricted_components},
                         {"unrestricted_components", c.unrestricted_components},
                         {"removed_volume_m3", num(c.removed_volume_m3)},
                         {"tets_removed", c.tets_removed},
                         {"leaves_refined", c.leaves_refined},
                         {"fragments_removed", c.fragments_removed},
                         {"fragment_volume_m3", num(c.fragment_volume_m3)},
                         {"snapped", c.snapped},
                         {"collapses", c.collapses},
                         {"new_triangles", c.new_triangles},
                         {"min_angle_deg", c.new_triangles > 0 ? num(c.min_angle_deg) : ojson(nullptr)},
                         {"min_edge_m", c.new_triangles > 0 ? num(c.min_edge_m) : ojson(nullptr)},
                         {"elements_after", c.elements_after},
                         {"dofs_after", c.dofs_after},
                         {"surface_vertices_after", c.surface_vertices_after},
                         {"latency_ms", c.latency_ms},
                         {"bridge_ms", c.bridge_ms},
                         {"settle_max_ms", c.settle_max_ms},
                         {"ms", ms}});
  }
  nlohmann::ordered_json probes = nlohmann::ordered_json::object();
  for (const ProbeResult& p : r.probes) probes[p.name] = {{"rest", vec(p.rest)}, {"displacement", vec(p.displacement)}};
  j["probes"] = probes;
  if (r.contact.present) {
    ojson tools = ojson::object(), bodies = ojson::object();
    for (const ToolContactSummary& t : r.contact.tools)
      tools[t.name] = {{"force_n", {{"max", num(t.max_force_n)}, {"final", vec(t.final_force_n)}}}};
    for (const BodyContactSummary& b : r.contact.bodies)
      bodies[b.name] = {{"position", vec(b.position)},
                        {"rotation_deg", vec(b.rotation_deg)},
                        {"velocity_m_s", vec(b.velocity_m_s)},
                        {"force_n", vec(b.force_n)}};
    j["contact"] = {{"max_penetration_m", num(r.contact.max_penetration_m)},
                    {"samples", r.contact.samples},
                    {"stiffness_pa_m", num(r.contact.stiffness_pa_m)},
                    {"tools", tools},
                    {"bodies", bodies}};
  } else {
    j["contact"] = nullptr;
  }
  j["stability"] = {{"finite", r.finite},
                    {"recoveries", r.recoveries},
                    {"failed_steps", r.failed_steps},
                    {"solver_failures", r.solver_failures},
                    {"nonfinite", r.nonfinite},
                    {"speed_limit", r.speed_limit},
                    {"energy_rejections", r.energy_rejections},
                    {"energy_projections", r.energy_projections},
                    {"energy_shortened", r.energy_shortened},
                    {"energy_removed_j", num(r.energy_removed_j)},
                    {"energy_unremoved_j", num(r.energy_unremoved_j)},
                    {"newton_unconverged", r.newton_unconverged},
                    {"max_speed_m_s", num(r.max_speed_m_s)},
                    {"min_volume_ratio", num(r.min_volume_ratio)},
                    {"energy_j", {{"kinetic", num(r.kinetic_j)}, {"elastic", num(r.elastic_j)}}}};
  if (r.track.enabled) {
    const StabilityTrack& t = r.track;
    j["stability"]["track"] = {{"energy_steps", t.energy_steps},
                               {"energy_rise_j", num(t.energy_rise_j)},
                               {"energy_scale_j", num(t.energy_scale_j)},
                               {"contact_work_j", num(t.contact_work_j)},
                               {"max_displacement_m", num(t.max_displacement_m)},
                               {"volume_change", num(t.volume_change)},
                               {"min_volume_change", num(t.min_volume_change)},
                               {"max_volume_change", num(t.max_volume_change)}};
  }
  j["surface"] = {{"closed", r.surface_closed},
                  {"self_intersecting", r.surface_self_intersecting},
                  {"rest_volume_m3", num(r.rest_volume_m3)},
                  {"components", r.surface_components},
                  {"genus", r.surface_genus},
                  {"object_removed", r.object_removed}};
  j["warnings"] = r.warnings;
  return j.dump(2) + "\n";
}

}  // namespace octocut::engine
