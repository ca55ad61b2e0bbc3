#include "octocut/engine/world.hpp"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>

#include "octocut/cutting/blade.hpp"
#include "octocut/cutting/cutting.hpp"
#include "octocut/cutting/material_mesher.hpp"
#include "octocut/cutting/mesh_check.hpp"
#include "octocut/engine/frame_writer.hpp"
#include "octocut/engine/io.hpp"
#include "octocut/engine/material_graph_cache.hpp"
#include "octocut/engine/mesh_io.hpp"
#include "octocut/engine/render_builder.hpp"
#include "octocut/engine/renderer.hpp"
#include "octocut/engine/scene_loader.hpp"
#include "octocut/engine/tool.hpp"
#include "octocut/sim/embedding.hpp"
#include "octocut/sim/parallel.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/sim/surface_check.hpp"
#include "report.hpp"

namespace octocut::engine {

namespace {

sim::Vec3 v3(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }
std::array<double, 3> a3(const sim::Vec3& v) { return {v.x(), v.y(), v.z()}; }
sim::Box3 box3(const SceneBox& b) { return {v3(b.min), v3(b.max)}; }

// Set by SIGINT/SIGTERM: the run stops at the next step and still writes its report.
std::atomic<bool> g_interrupted{false};
extern "C" void on_signal(int) { g_interrupted = true; }

std::string format_seconds(double t) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.6g s", t);
  return b;
}

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace

long step_count(const Scene& scene) {
  const double steps = std::ceil(scene.duration / scene.solver.dt - 1e-9);
  if (!(steps <= double(kMaxSteps)))
    throw SceneError(scene.file + ": /duration: duration / dt asks for " + std::to_string(steps) +
                     " steps; at most " + std::to_string(kMaxSteps) + " are allowed");
  return std::max(1L, long(steps));
}

namespace {

// The closed surface of a box: 8 vertices, 12 outward-oriented triangles.
sim::TriMesh closed_box_surface(const sim::Box3& b) {
  sim::TriMesh m;
  for (int k = 0; k < 8; ++k)
    m.vertices.emplace_back(k & 1 ? b.max.x() : b.min.x(), k & 2 ? b.max.y() : b.min.y(),
                            k & 4 ? b.max.z() : b.min.z());
  m.triangles = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                 {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  return m;
}

// True when some tool of the scene has cut events: only then are cut structures built.
bool scene_cuts(const Scene& scene) {
  return std::any_of(scene.tools.begin(), scene.tools.end(), [](const ToolSettings& t) { return !t.cuts.empty(); });
}

// Largest volume / cell_size^3 a material graph may be asked for. Mesh_3 makes about 5.4 tets per such cell (13.5k
// tets for the meniscus at 1 mm), so this allows about a million tets: 0.82M tets took 13 s for the meniscus.
constexpr double kMaxMaterialCells = 2e5;

}  // namespace

sim::ObjectModel build_object(const Scene& scene) { return build_scene_object(scene).model; }

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

SceneObject build_scene_object(const Scene& scene) {
  step_count(scene);
  const ObjectSettings& o = scene.object;
  SceneObject out;
  std::shared_ptr<const sim::MaterialSource> material;
  if (o.surface_is_box && scene_cuts(scene)) {
    // A box that tools cut: S as a welded grid and M as a Kuhn tet grid at the cell size, whose material is
    // exactly the box.
    const sim::Box3 box = box3(o.surface_box);
    const double h = o.material_graph_cell_size;
    const double cells = box.volume() / (h * h * h);
    if (!(cells <= kMaxMaterialCells))
      throw SceneError(scene.file + ": /object/material_graph/cell_size: " + std::to_string(h) +
                       " m is too small for this box (volume / cell_size^3 = " + std::to_string(cells) +
                       ", at most 2e5)");
    out.surface = sim::closed_box_grid(box, 24);
    const auto t0 = Clock::now();
    out.graph = std::make_shared<sim::MaterialGraph>(sim::box_tet_mesh(box, h));
    out.graph_ms = ms_since(t0);
    material = out.graph;
  } else if (o.surface_is_box) {
    material = std::make_shared<sim::BoxMaterial>(box3(o.surface_box));
    out.surface = closed_box_surface(box3(o.surface_box));
  } else {
    // The mesh: loaded, welded, validated and scaled to metres.
    try {
      LoadedMesh loaded = load_mesh(o.surface_path, MeshLoadOptions{o.scale, true, true});
      out.surface = std::move(loaded.mesh);
      for (std::string& w : loaded.warnings) out.warnings.push_back("/object/surface: " + o.surface_path + ": " + w);
    } catch (const MeshError& e) {
      throw SceneError(scene.file + ": /object/surface: " + e.what());
    }
    // M at the requested cell size, from the cache when possible.
    const double h = o.material_graph_cell_size;
    const double cells = sim::signed_volume(out.surface) / (h * h * h);
    if (!(cells <= kMaxMaterialCells))
      throw SceneError(scene.file + ": /object/material_graph/cell_size: " + std::to_string(h) +
                       " m is too small for this object (volume / cell_size^3 = " + std::to_string(cells) +
                       ", at most 2e5, about a million tets); check also /object/scale");
    try {
      MaterialGraphResult g = material_graph_for(out.surface, h);
      if (!g.warning.empty()) out.warnings.push_back("/object/material_graph: " + g.warning);
      out.graph_from_cache = g.from_cache;
      out.graph_ms = g.ms;
      out.graph = std::make_shared<sim::MaterialGraph>(std::move(g.mesh));
    } catch (const cutting::MeshingError& e) {
      throw SceneError(scene.file + ": /object/material_graph: " + e.what());
    } catch (const std::invalid_argument& e) {
      throw SceneError(scene.file + ": /object/material_graph: " + e.what());
    }
    material = out.graph;
  }
  const sim::Box3 bounds = sim::bounds(out.surface);

  // Root cube: given, or the material's bounding box made cubic and grown by 5%.
  sim::OctreeSpec spec;
  if (o.octree.has_root) {
    spec.root = {v3(o.octree.root_min), o.octree.root_size};
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
  for (const RefineRegion& r : o.octree.refine) spec.refine.push_back({box3(r.box), r.level});

  std::vector<sim::HandleSpec> handles;
  for (const Handle& h : o.handles) {
    sim::HandleSpec hs{box3(h.box), {}};
    for (const HandleKeyframe& k : h.keyframes) hs.keyframes.push_back({k.t, v3(k.translation), v3(k.rotation_deg)});
    handles.push_back(std::move(hs));
  }
  sim::MaterialParams params{o.material.young_modulus, o.material.poisson_ratio, o.material.density,
                             o.material.rayleigh_mass, o.material.rayleigh_stiffness};
  sim::ObjectModel model = [&] {
    try {
      return sim::ObjectModel::build(spec, material, params, std::move(handles));
    } catch (const std::invalid_argument& e) {
      throw SceneError(scene.file + ": /object/octree: " + e.what());
    }
  }();

  // Probes must lie in material.
  for (std::size_t i = 0; i < scene.probes.size(); ++i) {
    if (!model.embed(v3(scene.probes[i].point)))
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
  o.gravity = v3(s.gravity);
  o.linear_solver = s.linear_solver;
  o.tolerance = s.tolerance;
  o.max_iterations = s.max_iterations;
  o.threads = s.threads;
  o.max_speed = s.max_speed;
  return o;
}

RunResult run_scene(const Scene& scene, const RunOptions& options) {
  RunResult result;
  namespace fs = std::filesystem;
  const fs::path out(options.out_dir);
  result.report_path = (out / "report.json").string();

  // Everything that is bad input is found before the output directory is touched.
  std::optional<SceneObject> object;
  try {
    object = build_scene_object(scene);
  } catch (const SceneError& e) {
    result.exit_code = 2;
    result.error = e.what();
    return result;
  }
  // Render props are loaded with the scene's other inputs: a bad prop mesh is bad input.
  std::vector<RenderMesh> props;
  if (scene.render.enabled && !options.no_render) {
    try {
      const std::vector<sim::TriMesh> meshes = load_render_props(scene);
      for (std::size_t i = 0; i < meshes.size(); ++i) props.push_back(prop_mesh(meshes[i], scene.render.props[i].material));
    } catch (const SceneError& e) {
      result.exit_code = 2;
      result.error = e.what();
      return result;
    }
  }
  // Tools: blades validated and measured now (a bad blade is bad input), render meshes when drawn.
  struct ToolRuntime {
    sim::TriMesh blade;              // tool coordinates, m
    double inscribed_radius = 0.0;   // m
    std::optional<RenderMesh> mesh;  // drawn as metal
  };
  std::vector<ToolRuntime> tools;
  try {
    for (std::size_t i = 0; i < scene.tools.size(); ++i) {
      ToolRuntime tr;
      if (!scene.tools[i].cuts.empty()) {
        tr.blade = load_blade(scene, i);
        tr.inscribed_radius = cutting::inscribed_radius(tr.blade);
      }
      if (scene.render.enabled && !options.no_render && !scene.tools[i].mesh_path.empty())
        tr.mesh = prop_mesh(load_tool_mesh(scene, i), "metal");
      tools.push_back(std::move(tr));
    }
  } catch (const SceneError& e) {
    result.exit_code = 2;
    result.error = e.what();
    return result;
  }
  // Cut events in time order (ties: tool order, then the order in the tool's list).
  struct CutEvent {
    double t;
    std::size_t tool;
  };
  std::vector<CutEvent> events;
  for (std::size_t i = 0; i < scene.tools.size(); ++i)
    for (const auto& c : scene.tools[i].cuts) events.push_back({c.t, i});
  std::stable_sort(events.begin(), events.end(), [](const CutEvent& a, const CutEvent& b) { return a.t < b.t; });

  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) {
    result.exit_code = 1;
    result.error = options.out_dir + ": cannot create the output directory: " + ec.message();
    return result;
  }

  Report report;
  report.scene = scene.file;
  report.name = scene.name;

  // The renderer starts only when asked for and not vetoed; if EGL cannot start, the run ends with exit 2 and the
  // EGL error, with the report written.
  const bool rendering = scene.render.enabled && !options.no_render;
  std::unique_ptr<Renderer> renderer;
  if (rendering) {
    try {
      renderer = make_renderer();
    } catch (const std::exception& e) {
      result.exit_code = 2;
      result.error = scene.file + ": /render/enabled: cannot start the renderer: " + e.what() +
                     " (run with --no-render to skip rendering)";
      report.status = "failed";
      report.error = result.error;
      try {
        write_file_atomic(result.report_path, report_json(report));
      } catch (const std::exception&) {
        // The render error is the one to report.
      }
      return result;
    }
  }
  std::vector<double> render_ms;
  std::unique_ptr<FrameWriter> writer;
  const auto wall0 = Clock::now();
  std::vector<double> step_ms;
  g_interrupted = false;
  auto old_int = std::signal(SIGINT, on_signal);
  auto old_term = std::signal(SIGTERM, on_signal);

  try {
    report.warnings = object->warnings;
    cutting::CutObject cut_object;
    cut_object.surface = std::move(object->surface);
    cut_object.cut_faces.assign(cut_object.surface.triangles.size(), 0);
    cut_object.surface_checked = true;  // load_mesh rejects a self-intersecting S; a box cannot intersect itself
    cutting::index_surface(cut_object);  // the grid the cuts find S's faces near a blade with (O(|S|), once)
    const sim::TriMesh& surface = cut_object.surface;
    for (std::size_t i = 0; i < scene.tools.size(); ++i)
      if (scene.tools[i].collide)
        report.warnings.push_back("/tools/" + std::to_string(i) +
                                  "/collide: tool contact is not implemented yet; the tool passes through tissue");
    sim::Simulator sim(std::move(object->model), simulator_options(scene));
    object->graph.reset();  // M is held by the model alone (sim.model().material_graph())
    const sim::ObjectModel& m0 = sim.model();
    // Counts of the current revision and of S (at the start, and again at the end after the cuts).
    const auto record_counts = [&] {
      const sim::ObjectModel& m = sim.model();
      report.object_removed = cut_object.removed;
      report.elements = cut_object.removed ? 0 : m.num_elements();
      report.dofs = cut_object.removed ? 0 : m.num_dofs();
      report.hanging_slots = cut_object.removed ? 0 : m.dofs().hanging_slots;
      report.tets = cut_object.removed || !m.material_graph() ? 0 : m.material_graph()->num_tets();
      report.surface_vertices = long(surface.num_vertices());
      report.surface_triangles = long(surface.num_triangles());
      const sim::SurfaceCheck check = sim::check_surface(surface);
      report.surface_closed = check.closed && check.edge_manifold && check.oriented;
      report.surface_components = check.components;
      // Genus from the Euler characteristic of a closed surface: chi = V - E + F = 2 (components - genus).
      if (report.surface_closed && !surface.triangles.empty()) {
        const long chi = long(surface.num_vertices()) - long(3 * surface.num_triangles() / 2) + long(surface.num_triangles());
        report.surface_genus = (2 * long(check.components) - chi) / 2;
      }
    };
    record_counts();
    for (std::size_t h = 0; h < m0.handles().size(); ++h) {
      if (std::none_of(m0.dof_handle().begin(), m0.dof_handle().end(), [&](int d) { return d == int(h); }))
        report.warnings.push_back("/object/handles/" + std::to_string(h) + ": the handle holds no DOF");
    }
    if (scene.solver.mode == "static" &&
        std::none_of(m0.dof_handle().begin(), m0.dof_handle().end(), [](int h) { return h >= 0; }))
      report.warnings.push_back("/solver/mode: a static solve with no handle holding the object has no unique "
                                "equilibrium (rigid motions are free)");
    // S embedded in T by the Z-curve list (SPEC §2.4); the deformed surface follows the DOFs.
    sim::Executor surface_exec(scene.solver.threads);
    sim::SurfaceEmbedding embedding(m0, surface);
    if (embedding.num_fallback() > 0)
      report.warnings.push_back(std::to_string(embedding.num_fallback()) +
                                " surface vertices lie outside every leaf and are bound to the nearest one");
    // The deformed surface, recomputed after every step (positions and normals in parallel over vertices).
    std::vector<sim::Vec3> deformed, deformed_normals;
    const auto update_surface = [&] {
      if (cut_object.removed) {
        deformed.clear();
        deformed_normals.clear();
        return;
      }
      embedding.deformed_positions(sim.state().x, deformed, surface_exec);
      embedding.deformed_normals(surface, deformed, deformed_normals, surface_exec);
    };
    update_surface();
    auto write_surface = [&](const fs::path& path) {
      write_file_atomic(path, encode_ply_binary(sim::TriMesh{deformed, surface.triangles}));
    };
    if (scene.output.surface_final || scene.output.surface_every > 0)
      write_file_atomic(out / "surface_rest.ply", encode_ply_binary(surface));
    if (scene.output.surface_every > 0) fs::create_directories(out / "surfaces");
    if (scene.output.frames && options.no_render)
      report.warnings.push_back("/output/frames: --no-render given, no frames written");
    if (scene.output.frames && !scene.render.enabled)
      report.warnings.push_back("/output/frames: render.enabled is false, no frames written");

    // Rendering: the tissue surface bound to the octree once, a frame every `every` steps from the rest state on.
    EmbeddedSurface tissue;
    Camera camera;
    std::vector<sim::Vec3> slots;
    long frame = 0;
    const auto render_frame = [&] {
      const auto t0 = Clock::now();
      RenderScene rs;
      rs.width = scene.render.width;
      rs.height = scene.render.height;
      rs.msaa = scene.render.msaa;
      rs.camera = camera;
      const sim::ObjectModel& m = sim.model();
      m.dofs().prolong(sim.state().x, slots);
      if (cut_object.removed) {
        // Nothing left to draw of the tissue.
      } else if (!m.material_graph()) {
        rs.meshes.push_back(tissue_mesh(m, tissue, slots));
      } else {
        // The mesh surface S as the Z-curve embedding moved it after the last step, cut faces tinted.
        RenderMesh t = tissue_mesh(deformed, deformed_normals, surface.triangles);
        t.cut.assign(cut_object.cut_faces.begin(), cut_object.cut_faces.end());
        rs.meshes.push_back(std::move(t));
      }
      // Props at their pose now; the camera follows the one it is told to.
      for (std::size_t i = 0; i < props.size(); ++i) {
        const Eigen::Matrix4d pose = prop_pose(scene.render.props[i], sim.state().t);
        RenderMesh mesh = props[i];
        mesh.model = pose.cast<float>();
        rs.meshes.push_back(std::move(mesh));
        if (scene.render.props[i].name == scene.render.camera.follow_tool) {
          follow_tool(camera, pose.topRightCorner<3, 1>());
          rs.camera = camera;
        }
      }
      // Tools at their pose now.
      for (std::size_t i = 0; i < tools.size(); ++i) {
        const ToolPose pose = tool_pose(scene.tools[i], sim.state().t);
        if (tools[i].mesh) {
          RenderMesh mesh = *tools[i].mesh;
          Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
          T.topLeftCorner<3, 3>() = pose.rotation;
          T.topRightCorner<3, 1>() = pose.position;
          mesh.model = T.cast<float>();
          rs.meshes.push_back(std::move(mesh));
        }
        if (scene.tools[i].name == scene.render.camera.follow_tool) {
          follow_tool(camera, pose.position);
          rs.camera = camera;
        }
      }
      if (!cut_object.removed) add_overlays(rs, scene.render.overlays, m, slots, sim.state().x);
      Image image = renderer->render(rs);
      render_ms.push_back(ms_since(t0));
      if (writer) writer->push(frame, std::move(image));
      ++frame;
    };
    if (rendering) {
      // A box primitive's 12 triangles would shade flat under deformation: draw it as a finer grid of its faces.
      if (!m0.material_graph()) tissue = embed_surface(m0, box_surface(box3(scene.object.surface_box), 32));
      camera = make_camera(scene.render.camera, sim::bounds(surface));
      if (scene.output.frames) {
        const fs::path frames_dir = out / "frames";
        fs::create_directories(frames_dir, ec);
        if (ec) throw std::runtime_error(frames_dir.string() + ": cannot create the frames directory: " + ec.message());
        writer = std::make_unique<FrameWriter>(frames_dir, 4);
      }
      render_frame();
    }

    // Cuts: each event runs the pipeline on the blade where its tool is at the event's time.
    cutting::CutOptions cut_options;
    cut_options.fragments = scene.cutting.remove_fragments == "none"    ? cutting::FragmentPolicy::none
                            : scene.cutting.remove_fragments == "small" ? cutting::FragmentPolicy::small
                                                                        : cutting::FragmentPolicy::all;
    cut_options.fragment_volume = scene.cutting.fragment_volume;
    cut_options.verify = scene.cutting.verify;
    std::size_t next_event = 0;
    const auto run_due_cuts = [&] {
      while (next_event < events.size() && events[next_event].t <= sim.state().t + 1e-9 * scene.solver.dt) {
        const CutEvent ev = events[next_event++];
        const ToolPose pose = tool_pose(scene.tools[ev.tool], ev.t);
        cutting::CutRequest req;
        req.blade = tools[ev.tool].blade;
        for (sim::Vec3& p : req.blade.vertices) p = pose.rotation * p + pose.position;
        req.inscribed_radius = tools[ev.tool].inscribed_radius;
        const cutting::CutOutcome o = cutting::apply_cut(cut_object, sim, embedding, req, cut_options);
        CutSummary c;
        c.t = ev.t;
        c.tool = scene.tools[ev.tool].name;
        c.status = o.status;
        c.reason = o.reason;
        c.components = o.components;
        c.restricted_components = o.restricted_components;
        c.unrestricted_components = o.unrestricted;
        c.removed_volume_m3 = o.removed_volume;
        c.tets_removed = o.tets_removed;
        c.leaves_refined = o.leaves_refined;
        c.fragments_removed = o.fragments_removed;
        c.fragment_volume_m3 = o.fragment_volume;
        c.elements_after = cut_object.removed ? 0 : sim.model().num_elements();
        c.dofs_after = cut_object.removed ? 0 : sim.model().num_dofs();
        c.surface_vertices_after = long(cut_object.surface.num_vertices());
        c.ms = {o.ms.back_transform, o.ms.surface, o.ms.material_graph, o.ms.refine, o.ms.node_split,
                o.ms.embedding,      o.ms.solver_update, o.ms.total};
        report.cuts.push_back(c);
        if (o.status == "skipped")
          report.warnings.push_back("cut at t = " + format_seconds(ev.t) + " by " + c.tool + " skipped: " + o.reason);
        if (o.perturbed > 0)
          report.warnings.push_back("cut at t = " + format_seconds(ev.t) + " by " + c.tool +
                                    ": a degenerate blade position was moved by 1e-9 of the blade's size");
        if (o.unrestricted > 0)
          report.warnings.push_back("cut at t = " + format_seconds(ev.t) + " by " + c.tool +
                                    ": the blade also covered other material in rest space, and could not be kept off "
                                    "it (" + std::to_string(o.unrestricted) + " component(s)): it cut all of it");
        if (o.status == "ok") update_surface();
      }
    };
    run_due_cuts();
    for (const CutEvent& ev : events)
      if (ev.t > scene.duration)
        report.warnings.push_back("cut at t = " + format_seconds(ev.t) + " by " + scene.tools[ev.tool].name +
                                  " is after the end of the run and does not happen");

    // Timeline: fixed steps of dt up to the duration.
    const long steps = step_count(scene);
    const bool tty = options.progress && isatty(STDERR_FILENO);
    auto last_progress = Clock::now();
    for (long i = 0; i < steps; ++i) {
      if (g_interrupted) throw std::runtime_error("interrupted by a signal");
      const auto t0 = Clock::now();
      if (!cut_object.removed) {
        sim.step();
      } else {
        // Nothing left to simulate: time still runs for the tools and the renderer.
        sim::SimState st = sim.state();
        st.t += scene.solver.dt;
        sim.set_state(std::move(st));
      }
      update_surface();
      run_due_cuts();
      step_ms.push_back(ms_since(t0));
      report.steps = i + 1;
      if (scene.output.surface_every > 0 && (i + 1) % scene.output.surface_every == 0) {
        char name[32];
        std::snprintf(name, sizeof(name), "surface_%06ld.ply", i + 1);
        write_surface(out / "surfaces" / name);
      }
      if (rendering && (i + 1) % scene.render.every == 0) render_frame();
      if (tty && (ms_since(last_progress) > 200.0 || i + 1 == steps)) {
        last_progress = Clock::now();
        std::fprintf(stderr, "\r[octocut] step %ld/%ld  t = %.4f s  %.2f ms/step", i + 1, steps, sim.state().t,
                     step_ms.back());
        if (rendering) std::fprintf(stderr, "  frame %ld  %.1f ms/frame", frame, render_ms.back());
        std::fprintf(stderr, "   ");
        if (i + 1 == steps) std::fprintf(stderr, "\n");
      }
    }

    // Results: counts of the final revision, S after the cuts, probes, energies, stability counters.
    const sim::ObjectModel& m = sim.model();
    record_counts();
    // S is free of self-intersections: load_mesh rejects a self-intersecting mesh (CGAL, exact predicates), a box
    // grid cannot intersect itself, and every cut checks its changed faces (cutting.verify) or is skipped. With
    // verification off, the whole surface is checked here.
    report.surface_self_intersecting =
        !scene.cutting.verify && !report.cuts.empty() && !surface.triangles.empty() &&
        cutting::find_self_intersection(surface).has_value();
    report.rest_volume_m3 = sim::signed_volume(surface);
    for (const Probe& p : scene.probes) {
      const auto e = cut_object.removed ? std::nullopt : m.embed(v3(p.point));
      if (!e) {
        report.warnings.push_back("probe " + p.name + ": its point was cut away");
        report.probes.push_back({p.name, p.point, {NAN, NAN, NAN}});
        continue;
      }
      report.probes.push_back({p.name, p.point, a3(sim.position(*e) - v3(p.point))});
    }
    bool finite = true;
    for (std::size_t d = 0; d < sim.state().x.size(); ++d)
      finite = finite && sim.state().x[d].allFinite() && sim.state().v[d].allFinite();
    report.finite = finite;
    const sim::StabilityStats& st = sim.stats();
    report.recoveries = st.recoveries;
    report.failed_steps = st.failed_steps;
    report.solver_failures = st.solver_failures;
    report.nonfinite = st.nonfinite;
    report.speed_limit = st.speed_limit;
    report.newton_unconverged = st.newton_unconverged;
    report.max_speed_m_s = st.max_speed;
    report.kinetic_j = cut_object.removed ? 0.0 : sim.kinetic_energy();
    report.elastic_j = cut_object.removed ? 0.0 : sim.elastic_energy();
    report.sim_time_s = sim.state().t;
    if (st.failed_steps > 0)
      report.warnings.push_back(std::to_string(st.failed_steps) +
                                " steps failed at the smallest dt and were reset (velocities zeroed)");
    if (st.newton_unconverged > 0)
      report.warnings.push_back(std::to_string(st.newton_unconverged) + " static solves stopped unconverged");
    if (!finite) throw std::runtime_error("the state is not finite");
    if (scene.output.surface_final) write_surface(out / "surface_final.ply");
    // Every queued frame is on disk before the run counts as done.
    if (writer) writer->finish();
  } catch (const std::exception& e) {
    report.status = "failed";
    report.error = e.what();
    result.exit_code = 1;
    result.error = e.what();
  }
  std::signal(SIGINT, old_int);
  std::signal(SIGTERM, old_term);

  // A failed run still keeps every frame written before the failure.
  if (writer) {
    try {
      writer->finish();
    } catch (const std::exception&) {
      // Already reported through the run's error.
    }
    report.frame_write_ms = TimingSummary::of(writer->write_ms());
    report.frames = writer->written();
    writer.reset();
  }
  report.render_ms = TimingSummary::of(render_ms);
  report.frames_rendered = long(render_ms.size());
  report.step_ms = TimingSummary::of(step_ms);
  report.wall_time_s = ms_since(wall0) / 1000.0;
  result.cuts = report.cuts;
  try {
    write_file_atomic(result.report_path, report_json(report));
  } catch (const std::exception& e) {
    result.exit_code = 1;
    result.error = e.what();
  }
  return result;
}

}  // namespace octocut::engine
