#include "octocut/engine/run/cut_command.hpp"

#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>

#include "octocut/cutting/blade.hpp"
#include "octocut/cutting/mesh_check.hpp"
#include "octocut/cutting/surface_cut.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/io/material_graph_cache.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/sim/material_graph.hpp"
#include "octocut/sim/surface_check.hpp"
#include "octocut/sim/timing.hpp"

namespace octocut::engine {

namespace {
using sim::Clock;
using sim::ms_since;
nlohmann::ordered_json num(double v) { return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr); }
}  // namespace

CutCommandResult run_cut_command(const CutCommandOptions& o) {
  CutCommandResult res;
  if (!(o.scale > 0.0) || !std::isfinite(o.scale)) return {2, "--scale: must be a positive number"};
  if (!(o.cell_size >= 0.0) || !std::isfinite(o.cell_size)) return {2, "--cell-size: must be a positive number"};
  // Both inputs are checked before anything is written: a bad blade writes nothing.
  sim::TriMesh surface, blade;
  try {
    surface = load_mesh(o.surface_path, MeshLoadOptions{o.scale, true, true}).mesh;
  } catch (const MeshError& e) {
    return {2, std::string("--surface: ") + e.what()};
  }
  try {
    blade = load_mesh(o.blade_path, MeshLoadOptions{o.scale, true, true}).mesh;
  } catch (const MeshError& e) {
    return {2, std::string("--blade: ") + e.what()};
  }
  const double v_in = sim::signed_volume(surface);
  // M at the cell size: 1 mm by default, coarser when the object would need more than 2e5 cells.
  double h = o.cell_size > 0.0 ? o.cell_size : 0.001;
  if (v_in / (h * h * h) > 2e5) {
    if (o.cell_size > 0.0) return {2, "--cell-size: too small for this surface (volume / cell_size^3 > 2e5)"};
    h = std::cbrt(v_in / 2e5);
  }

  const auto t_total = Clock::now();
  auto t0 = Clock::now();
  cutting::SurfaceCutOptions so;
  so.verify = o.verify;
  // A degenerate blade position that the exact boolean cannot round is moved by 1e-9 (then 1e-7, 1e-5) of the blade's
  // size, as in the cut pipeline; the report says so.
  auto [cut, perturbed] = cutting::cut_surface_perturbing(surface, blade, so);
  const double ms_surface = ms_since(t0);

  // Stage 3 on a fresh M: the tets the blade touches.
  t0 = Clock::now();
  int tets = 0, tets_removed = 0;
  std::string m_note;
  try {
    MaterialGraphResult g = material_graph_for(surface, h);
    const sim::MaterialGraph graph(std::move(g.mesh));
    tets = graph.num_tets();
    tets_removed = int(cutting::tets_touched(graph, cutting::BladeVolume(blade)).size());
  } catch (const std::exception& e) {
    m_note = std::string("material graph: ") + e.what();
  }
  const double ms_graph = ms_since(t0);
  const double ms_total = ms_since(t_total);

  const bool ok = cut.status == cutting::SurfaceCutStatus::ok;
  const bool noop = cut.status == cutting::SurfaceCutStatus::no_op;
  const sim::TriMesh& result = ok ? cut.mesh : surface;
  const sim::SurfaceCheck check = sim::check_surface(result);
  const bool closed = check.closed && check.edge_manifold && check.oriented;
  const bool self_int = !(ok || noop) ? false : (!result.triangles.empty() && cutting::find_self_intersection(result).has_value());
  const double v_out = (ok || noop) ? sim::signed_volume(result) : v_in;

  nlohmann::ordered_json j;
  j["schema"] = "octocut.cut/1";
  j["status"] = ok ? "ok" : noop ? "no-op" : "failed";
  j["reason"] = cut.reason.empty() ? (m_note.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(m_note))
                                   : nlohmann::ordered_json(cut.reason);
  j["input_volume_m3"] = num(v_in);
  j["output_volume_m3"] = num(v_out);
  j["removed_volume_m3"] = num(ok ? cut.removed_volume : 0.0);
  j["closed"] = closed;
  j["self_intersecting"] = self_int;
  j["components"] = check.components;
  j["input_vertices"] = surface.num_vertices();
  j["output_vertices"] = result.num_vertices();
  j["input_triangles"] = surface.num_triangles();
  j["output_triangles"] = result.num_triangles();
  j["patch_triangles"] = cut.patch_triangles;
  j["blade_perturbed"] = perturbed;  // 0, or 1 / 2 / 3: the blade was moved by 1e-9 / 1e-7 / 1e-5 of its size
  j["material_graph"] = {{"cell_size_m", h}, {"tets", tets}, {"tets_removed", tets_removed}};
  j["ms"] = {{"surface", ms_surface}, {"material_graph", ms_graph}, {"total", ms_total}};
  try {
    if (ok || noop) save_mesh(o.out_path, result, o.ply_float ? PlyPrecision::single : PlyPrecision::double_);
    if (!o.report_path.empty()) write_file_atomic(o.report_path, j.dump(2) + "\n");
  } catch (const std::exception& e) {
    return {1, e.what()};
  }
  if (!(ok || noop)) return {1, "the cut failed: " + cut.reason};
  char line[256];
  std::snprintf(line, sizeof(line), "%s: removed %.6g m^3 in %.2f ms (surface %.2f ms); %zu -> %zu vertices",
                ok ? "ok" : "no-op", ok ? cut.removed_volume : 0.0, ms_total, ms_surface, surface.num_vertices(),
                result.num_vertices());
  return {0, line};
}

}  // namespace octocut::engine
