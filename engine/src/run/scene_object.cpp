// Building a scene's object and reading its other inputs: everything that can be bad input, before any output.
#include "octocut/engine/run/scene_object.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "octocut/cutting/material_mesher.hpp"
#include "octocut/engine/io/material_graph_cache.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/sim/pose.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/sim/timing.hpp"
#include "scene/scene_schema.hpp"

namespace octocut::engine {

const char* to_string(MaterialGraphSource source) {
  switch (source) {
    case MaterialGraphSource::box: return "box";
    case MaterialGraphSource::cache: return "cache";
    case MaterialGraphSource::meshed: return "meshed";
  }
  return "box";
}

bool scene_cuts(const Scene& scene) {
  return std::any_of(scene.tools.begin(), scene.tools.end(), [](const ToolSettings& t) { return !t.cuts.empty(); });
}

long step_count(const Scene& scene) {
  const double steps = std::ceil(scene.duration / scene.solver.dt - 1e-9);
  if (!(steps <= double(kMaxSteps)))
    throw SceneError(scene.file + ": /duration: duration / dt asks for " + schema::format_number(steps) +
                     " steps; at most " + std::to_string(kMaxSteps) + " are allowed");
  return std::max(1L, long(steps));
}

namespace {

// Largest volume / cell_size^3 a material graph may be asked for. Mesh_3 makes about 5.4 tets per such cell (13.5k
// tets for the meniscus at 1 mm), so this allows about a million tets: 0.82M tets took 13 s for the meniscus.
constexpr double kMaxMaterialCells = 2e5;

}  // namespace

std::vector<sim::TriMesh> load_render_props(const Scene& scene) {
  std::vector<sim::TriMesh> meshes;
  for (std::size_t i = 0; i < scene.render.props.size(); ++i) {
    const RenderProp& p = scene.render.props[i];
    try {
      meshes.push_back(load_mesh(p.mesh_path, MeshLoadOptions{p.scale, true, false}).mesh);
    } catch (const MeshError& e) {
      throw SceneError(scene.file + ": /render/props/" + std::to_string(i) + "/mesh: " + e.what());
    }
  }
  return meshes;
}

sim::MaterialParams material_params(const Material& material) {
  sim::MaterialParams p{material.young_modulus, material.poisson_ratio, material.density, material.rayleigh_mass,
                        material.rayleigh_stiffness};
  if (material.element != "bbar" && material.element != "trilinear")
    throw std::invalid_argument("element must be \"bbar\" or \"trilinear\", not \"" + material.element + "\"");
  p.element = material.element == "trilinear" ? sim::HexFormulation::trilinear : sim::HexFormulation::bbar;
  return p;
}

SceneObject build_scene_object(const Scene& scene, bool cuttable) {
  step_count(scene);
  const ObjectSettings& o = scene.object;
  SceneObject out;
  std::shared_ptr<const sim::MaterialSource> material;
  if (o.surface_is_box && (cuttable || scene_cuts(scene))) {
    // A box that tools cut: S as a welded grid and M as a Kuhn tet grid at the cell size, whose material is
    // exactly the box.
    const sim::Box3 box = to_box3(o.surface_box);
    const double h = o.material_graph_cell_size;
    const double cells = box.volume() / (h * h * h);
    if (!(cells <= kMaxMaterialCells))
      throw SceneError(scene.file + ": /object/material_graph/cell_size: " + schema::format_number(h) +
                       " m is too small for this box (volume / cell_size^3 = " + schema::format_number(cells) +
                       ", at most 2e5)");
    out.surface = sim::closed_box_grid(box, 24);
    const auto t0 = sim::Clock::now();
    material = std::make_shared<sim::MaterialGraph>(sim::box_tet_mesh(box, h));
    out.graph_ms = sim::ms_since(t0);
  } else if (o.surface_is_box) {
    material = std::make_shared<sim::BoxMaterial>(to_box3(o.surface_box));
    out.surface = sim::closed_box_grid(to_box3(o.surface_box), 1);
  } else {
    // The mesh: loaded, welded, validated and scaled to metres.
    try {
      LoadedMesh loaded = load_mesh(o.surface_path, MeshLoadOptions{o.scale, true, true});
      out.surface = std::move(loaded.mesh);
      for (std::string& w : loaded.warnings) out.warnings.push_back("/object/surface: " + w);  // w names the file
    } catch (const MeshError& e) {
      throw SceneError(scene.file + ": /object/surface: " + e.what());
    }
    // M at the requested cell size, from the cache when possible.
    const double h = o.material_graph_cell_size;
    const double cells = sim::signed_volume(out.surface) / (h * h * h);
    if (!(cells <= kMaxMaterialCells))
      throw SceneError(scene.file + ": /object/material_graph/cell_size: " + schema::format_number(h) +
                       " m is too small for this object (volume / cell_size^3 = " + schema::format_number(cells) +
                       ", at most 2e5, about a million tets); check also /object/scale");
    try {
      MaterialGraphResult g = material_graph_for(out.surface, h);
      if (!g.warning.empty()) out.warnings.push_back("/object/material_graph: " + g.warning);
      out.graph_source = g.from_cache ? MaterialGraphSource::cache : MaterialGraphSource::meshed;
      out.graph_ms = g.ms;
      material = std::make_shared<sim::MaterialGraph>(std::move(g.mesh));
    } catch (const cutting::MeshingError& e) {
      throw SceneError(scene.file + ": /object/material_graph: " + e.what());
    } catch (const std::invalid_argument& e) {
      throw SceneError(scene.file + ": /object/material_graph: " + e.what());
    }
  }
  const sim::Box3 bounds = sim::bounds(out.surface);

  // Root cube: given, or the material's bounding box made cubic and grown by 5%.
  sim::OctreeSpec spec;
  if (o.octree.has_root) {
    spec.root = {to_vec3(o.octree.root_min), o.octree.root_size};
    const sim::Box3 root_box{spec.root.min, spec.root.min + sim::Vec3::Constant(spec.root.size)};
    if (!root_box.contains(bounds.min, 1e-12 * spec.root.size) || !root_box.contains(bounds.max, 1e-12 * spec.root.size))
      throw SceneError(scene.file + ": /object/octree/root: the root cube does not contain the object");
  } else {
    const double size = 1.05 * (bounds.max - bounds.min).maxCoeff();
    spec.root = {0.5 * (bounds.min + bounds.max) - sim::Vec3::Constant(0.5 * size), size};
  }
  // `uniform`: no adaptivity, the whole object at max_level.
  spec.base_level = o.octree.uniform ? o.octree.max_level : o.octree.base_level;
  spec.max_level = o.octree.max_level;
  for (const RefineRegion& r : o.octree.refine) spec.refine.push_back({to_box3(r.box), r.level});

  std::vector<sim::HandleSpec> handles;
  for (const Handle& h : o.handles) {
    sim::HandleSpec hs{to_box3(h.box), {}};
    for (const HandleKeyframe& k : h.keyframes) hs.keyframes.push_back({k.t, to_vec3(k.translation), to_vec3(k.rotation_deg)});
    handles.push_back(std::move(hs));
  }
  const sim::MaterialParams params = material_params(o.material);
  sim::ObjectModel model = [&] {
    try {
      return sim::ObjectModel::build(spec, material, params, std::move(handles));
    } catch (const std::invalid_argument& e) {
      throw SceneError(scene.file + ": /object/octree: " + e.what());
    }
  }();

  // Probes must lie in material.
  for (std::size_t i = 0; i < scene.probes.size(); ++i) {
    if (!model.embed(to_vec3(scene.probes[i].point)))
      throw SceneError(scene.file + ": /probes/" + std::to_string(i) + "/point: outside the object's material");
  }
  out.model = std::move(model);
  return out;
}

sim::SimulatorOptions simulator_options(const Scene& scene) {
  const SolverSettings& s = scene.solver;
  sim::SimulatorOptions o;
  o.dynamic = s.mode == "dynamic";
  o.dt = s.dt;
  o.gravity = to_vec3(s.gravity);
  o.linear_solver = s.linear_solver;
  o.tolerance = s.tolerance;
  o.max_iterations = s.max_iterations;
  o.factor_lag = s.factor_lag;
  o.threads = s.threads;
  o.max_speed = s.max_speed;
  o.energy_guard = s.energy_guard;
  return o;
}

}  // namespace octocut::engine
