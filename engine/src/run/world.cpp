// engine::World: one running scene. See world.hpp.
#include "octocut/engine/run/world.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "octocut/cutting/blade.hpp"
#include "octocut/cutting/cutting.hpp"
#include "octocut/cutting/mesh_check.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/engine/render/camera.hpp"
#include "octocut/engine/render/crease.hpp"
#include "octocut/engine/render/render_builder.hpp"
#include "octocut/engine/run/scene_object.hpp"
#include "octocut/engine/run/tool.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/sim/embedding.hpp"
#include "octocut/sim/parallel.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/sim/surface_check.hpp"
#include "octocut/sim/timing.hpp"
#include "run/contact_world.hpp"
#include "stability_track.hpp"

namespace octocut::engine {

namespace {

std::array<double, 3> a3(const sim::Vec3& v) { return {v.x(), v.y(), v.z()}; }

std::string format_seconds(double t) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.6g s", t);
  return b;
}

std::string format_fraction(double f) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.0e", f);
  return b;
}

// A tool at run time: its keyframes as poses, its blade (loaded for tools with cut events, or on the first cut_now),
// its render mesh when drawn, and the pose a person set.
struct ToolRuntime {
  std::vector<sim::PoseKeyframe> keyframes;  // tool coordinates to world
  std::optional<sim::TriMesh> blade;         // tool coordinates, m
  double inscribed_radius = 0.0;             // m
  std::optional<RenderMesh> mesh;            // drawn as metal
  std::optional<sim::Pose> driven;           // set_tool_pose: overrides the keyframes
};

// A render prop at run time: its mesh and its keyframes.
struct PropRuntime {
  RenderMesh mesh;
  std::vector<sim::PoseKeyframe> keyframes;
};

// A cut event of the timeline (ties: tool order, then the order in the tool's list).
struct CutEvent {
  double t;
  std::size_t tool;
};

cutting::CutOptions cut_options(const CuttingSettings& s) {
  cutting::CutOptions o;
  o.fragments = s.remove_fragments == "none"    ? cutting::FragmentPolicy::none
                : s.remove_fragments == "small" ? cutting::FragmentPolicy::small
                                                : cutting::FragmentPolicy::all;
  o.fragment_volume = s.fragment_volume;
  o.verify = s.verify;
  o.min_feature = s.min_feature;
  return o;
}

}  // namespace

bool state_finite(const sim::SimState& state) {
  for (std::size_t d = 0; d < state.x.size(); ++d)
    if (!state.x[d].allFinite() || !state.v[d].allFinite()) return false;
  return true;
}

struct World::Impl {
  Scene scene;
  WorldOptions options;
  bool rendering = false;
  long total_steps = 0;
  long steps = 0;
  std::vector<double> step_ms;
  // The cuts whose kSettleSteps steps have not all run yet: cuts[] index, steps left (kSettleSteps: the next step is
  // the first after the cut, which counts in its latency too).
  std::vector<std::pair<std::size_t, int>> settling;

  MaterialGraphSource graph_source = MaterialGraphSource::box;
  cutting::CutObject object;                           // S (the one copy), M, the face grid
  std::unique_ptr<sim::Simulator> sim;                 // model revision and state
  std::unique_ptr<sim::SurfaceEmbedding> embedding;    // S bound to the current model
  sim::Executor surface_exec;                          // deformed positions and normals, parallel over vertices
  std::vector<sim::Vec3> deformed;                     // S after the last step (|V|, m), once surface_now() ran
  bool deformed_stale = true;                          // `deformed` is not yet that of the current state
  long surface_revision = 0;                           // counts the changes of S (cuts)
  // The tissue's smooth patches for drawing, made when a frame first needs them after S changed.
  mutable CreaseTopology crease;
  mutable long crease_revision = -1;

  std::vector<ToolRuntime> tools;
  std::vector<PropRuntime> props;
  std::vector<CutEvent> events;
  std::size_t next_event = 0;
  cutting::CutOptions cut_options;

  // Contact (only when the scene collides): the Bullet world and S's collision samples.
  std::unique_ptr<ContactWorld> contact;
  sim::ContactSamples samples;
  std::vector<sim::Contact> drawn_contacts;  // the last step's contacts, kept only for the contact overlay
  double contact_stiffness = 0.0;   // Pa/m
  double contact_resolution = 0.0;  // m, the finest leaf at the start

  std::vector<std::optional<RenderMesh>> body_meshes;  // per rigid body when drawn (body frame)

  EmbeddedSurface box_tissue;  // a box primitive drawn as a finer grid of its faces (its 12 triangles shade flat)
  Camera camera;               // the scene's camera before it follows a tool

  std::vector<CutSummary> cuts;
  std::vector<std::string> warnings;
  std::optional<StabilityTracker> track;  // output.stability_track

  Impl(const Scene& s, const WorldOptions& o);
  void load_tools();
  void load_props();
  void bind_surface();
  void check_start();
  void ensure_blade(std::size_t tool);
  void surface_changed();
  const std::vector<sim::Vec3>& surface_now();
  void build_contact();
  void load_body_meshes();
  void refresh_samples();
  void contact_before_step();
  void contact_after_step();
  CutSummary cut(std::size_t tool, double t, bool scheduled);
  void run_due_cuts(std::vector<CutSummary>& out);
  [[nodiscard]] sim::Pose tool_pose(std::size_t tool, double t) const;
  [[nodiscard]] bool handles_move_after(double t) const;
  void record_counts(Report& r) const;
  void record_state(Report& r) const;
  void record_contact(Report& r) const;
};

World::Impl::Impl(const Scene& s, const WorldOptions& o)
    : scene(s), options(o), rendering(s.render.enabled && o.render), total_steps(step_count(s)),
      surface_exec(s.solver.threads) {
  // Everything that is bad input is found here, before any output: the object, the props, the blades.
  SceneObject built = build_scene_object(scene, o.cuttable);
  warnings = std::move(built.warnings);
  graph_source = built.graph_source;
  if (rendering) load_props();
  load_tools();

  // The cut object owns S and M; S was checked when it was loaded (load_mesh rejects a self-intersecting S, a box
  // cannot intersect itself).
  object.surface = std::move(built.surface);
  object.cut_faces.assign(object.surface.triangles.size(), 0);
  object.surface_checked = true;
  // The grid that finds S's faces near a blade, only for a world that cuts (O(|S|), once); otherwise the first
  // cut_now builds it.
  if (!events.empty() || o.cuttable) cutting::index_surface(object);
  cut_options = engine::cut_options(scene.cutting);

  sim = std::make_unique<sim::Simulator>(std::move(built.model), simulator_options(scene));
  check_start();
  bind_surface();
  if (scene_collides(scene)) build_contact();
  if (scene.output.stability_track) {
    track.emplace();
    track->start(*sim, to_vec3(scene.solver.gravity));
  }
}

void World::Impl::build_contact() {
  // The penalty from E and the finest leaf (unless given), the samples at that resolution, the Bullet world.
  const sim::ObjectModel& m0 = sim->model();
  double h = 0.0;
  for (double e : m0.edge()) h = h == 0.0 ? e : std::min(h, e);
  if (!(h > 0.0)) h = 1e-3;
  contact_resolution = h;
  contact_stiffness =
      scene.contact.has_stiffness ? scene.contact.stiffness : default_contact_stiffness(scene.object.material.young_modulus, h);
  std::vector<sim::TriMesh> shapes(scene.tools.size());
  for (std::size_t i = 0; i < scene.tools.size(); ++i) {
    const ToolSettings& t = scene.tools[i];
    if (!t.collide) continue;
    if (!t.mesh_path.empty()) {
      try {
        shapes[i] = load_mesh(t.mesh_path, MeshLoadOptions{t.scale, true, true}).mesh;
      } catch (const MeshError& e) {
        throw SceneError(scene.file + ": /tools/" + std::to_string(i) + "/mesh: " + e.what());
      }
    } else if (!t.blade_is_cylinder) {
      ensure_blade(i);
      shapes[i] = *tools[i].blade;
    }
  }
  // Triangle meshes are searched within h / 2 of each sample: deeper penetrations than that are not expected with the
  // penalty in the implicit system, and a small box keeps the BVH queries cheap.
  contact = std::make_unique<ContactWorld>(scene, shapes, contact_stiffness, 0.5 * h);
  if (rendering) load_body_meshes();
  if (scene.solver.mode == "static")
    warnings.push_back("/solver/mode: contact acts in dynamic mode only; this static scene ignores it");
  refresh_samples();
}

namespace {
// A UV sphere of `radius` about the origin, m (for drawing).
sim::TriMesh sphere_mesh(double radius, int segments, int rings) {
  sim::TriMesh m;
  m.vertices.push_back({0, 0, -radius});
  for (int r = 1; r < rings; ++r) {
    const double phi = M_PI * r / rings - M_PI / 2;
    for (int k = 0; k < segments; ++k) {
      const double th = 2 * M_PI * k / segments;
      m.vertices.push_back(radius * sim::Vec3(std::cos(phi) * std::cos(th), std::cos(phi) * std::sin(th), std::sin(phi)));
    }
  }
  m.vertices.push_back({0, 0, radius});
  const int top = int(m.vertices.size()) - 1;
  auto at = [&](int r, int k) { return 1 + (r - 1) * segments + (k % segments); };
  for (int k = 0; k < segments; ++k) {
    m.triangles.push_back({0, at(1, k + 1), at(1, k)});
    m.triangles.push_back({top, at(rings - 1, k), at(rings - 1, k + 1)});
    for (int r = 1; r + 1 < rings; ++r) {
      m.triangles.push_back({at(r, k), at(r, k + 1), at(r + 1, k + 1)});
      m.triangles.push_back({at(r, k), at(r + 1, k + 1), at(r + 1, k)});
    }
  }
  return m;
}
}  // namespace

void World::Impl::load_body_meshes() {
  // What each rigid body looks like: its shape in the body frame, shaded as metal, bone or glass.
  for (std::size_t i = 0; i < scene.rigid_bodies.size(); ++i) {
    const RigidBodySettings& b = scene.rigid_bodies[i];
    body_meshes.emplace_back();
    if (b.render == "none") continue;
    const RigidShape& sh = b.shape;
    sim::TriMesh mesh;
    if (sh.kind == "sphere") mesh = sphere_mesh(sh.radius, 48, 24);
    if (sh.kind == "cylinder") mesh = sim::cylinder_mesh(sh.radius, sh.height, 64);
    if (sh.kind == "box") {
      const sim::Vec3 half = 0.5 * to_vec3(sh.size);
      mesh = sim::box_face_grids({-half, half}, 1);
    }
    if (sh.kind == "mesh") mesh = load_mesh(sh.mesh_path, MeshLoadOptions{sh.scale, false, false}).mesh;
    body_meshes.back() = prop_mesh(mesh, b.render);
  }
}

void World::Impl::refresh_samples() {
  if (!contact) return;
  drawn_contacts.clear();  // their DOF rows belong to the model before the cut
  const std::vector<sim::Vec3> before = std::move(samples.rest);
  if (sim->empty()) samples = sim::ContactSamples{};
  else samples = sim::build_contact_samples(sim->model(), object.surface, *embedding, contact_resolution);
  if (samples.begin.empty()) samples.begin.push_back(0);
  // The samples the cut left keep what the colliders' queries know of where they are.
  contact->remap_samples(same_rest_positions(before, samples.rest));
}

void World::Impl::contact_before_step() {
  if (!contact || sim->empty()) return;
  const double t = sim->state().t, dt = scene.solver.dt;
  std::vector<sim::Pose> now, next;
  for (std::size_t i = 0; i < tools.size(); ++i) {
    now.push_back(tool_pose(i, t));
    next.push_back(tool_pose(i, t + dt));
  }
  std::vector<sim::Contact> found = contact->find(samples, sim->state().x, t, dt, now, next, &sim->executor());
  if (rendering && scene.render.overlays.contacts) drawn_contacts = found;
  else drawn_contacts.clear();
  sim->set_contacts(std::move(found));
}

void World::Impl::contact_after_step() {
  if (!contact) return;
  const double dt = scene.solver.dt, t = sim->state().t - dt;
  std::vector<sim::Pose> next;
  for (std::size_t i = 0; i < tools.size(); ++i) next.push_back(tool_pose(i, t + dt));
  contact->finish(sim->contact_outcomes(), t, dt, next);
}

void World::Impl::load_props() {
  const std::vector<sim::TriMesh> meshes = load_render_props(scene);
  for (std::size_t i = 0; i < meshes.size(); ++i) {
    PropRuntime p;
    p.mesh = prop_mesh(meshes[i], scene.render.props[i].material);
    p.keyframes = pose_keyframes(scene.render.props[i].keyframes);
    props.push_back(std::move(p));
  }
}

void World::Impl::load_tools() {
  // Blades validated and measured now for tools with cut events (a bad blade is bad input); meshes when drawn.
  for (std::size_t i = 0; i < scene.tools.size(); ++i) {
    const ToolSettings& t = scene.tools[i];
    tools.emplace_back();
    tools.back().keyframes = pose_keyframes(t.keyframes);
    if (!t.cuts.empty()) ensure_blade(i);
    if (rendering && !t.mesh_path.empty()) tools.back().mesh = prop_mesh(load_tool_mesh(scene, i), "metal");
    for (const ToolCut& c : t.cuts) events.push_back({c.t, i});
  }
  std::stable_sort(events.begin(), events.end(), [](const CutEvent& a, const CutEvent& b) { return a.t < b.t; });
  for (const CutEvent& ev : events)
    if (ev.t > scene.duration)
      warnings.push_back("cut at t = " + format_seconds(ev.t) + " by " + scene.tools[ev.tool].name +
                         " is after the end of the run and does not happen");
}

void World::Impl::ensure_blade(std::size_t i) {
  ToolRuntime& tr = tools.at(i);
  if (tr.blade) return;
  std::vector<std::string> blade_warnings;
  tr.blade = load_blade(scene, i, &blade_warnings);
  tr.inscribed_radius = cutting::inscribed_radius(*tr.blade);
  for (std::string& w : blade_warnings) warnings.push_back(std::move(w));
}

void World::Impl::check_start() {
  // Handles that hold nothing, and a static solve that nothing holds.
  const sim::ObjectModel& m0 = sim->model();
  for (std::size_t h = 0; h < m0.handles().size(); ++h) {
    if (std::none_of(m0.dof_handle().begin(), m0.dof_handle().end(), [&](int d) { return d == int(h); }))
      warnings.push_back("/object/handles/" + std::to_string(h) + ": the handle holds no DOF");
  }
  if (scene.solver.mode == "static" &&
      std::none_of(m0.dof_handle().begin(), m0.dof_handle().end(), [](int h) { return h >= 0; }))
    warnings.push_back("/solver/mode: a static solve with no handle holding the object has no unique "
                       "equilibrium (rigid motions are free)");
}

void World::Impl::bind_surface() {
  // S embedded in T by the Z-curve list (SPEC §2.4); the deformed surface follows the DOFs.
  const sim::ObjectModel& m0 = sim->model();
  embedding = std::make_unique<sim::SurfaceEmbedding>(m0, object.surface);
  if (embedding->num_fallback() > 0)
    warnings.push_back(std::to_string(embedding->num_fallback()) +
                       " surface vertices lie outside every leaf and are bound to the nearest one");
  surface_changed();
  if (!rendering) return;
  if (!m0.material_graph()) {
    const sim::Box3 box = to_box3(scene.object.surface_box);
    box_tissue = embed_surface(m0, sim::box_face_grids(box, 32));
  }
  camera = make_camera(scene.render.camera, sim::bounds(object.surface));
}

// The state or S changed: the deformed surface is computed again when someone asks for it (surface_now), not at
// every step. A run without frames or surface outputs never needs it (meniscus_punch: 0.06-0.08 ms of a 3-4 ms step).
void World::Impl::surface_changed() {
  deformed_stale = true;
  if (sim->empty()) deformed.clear();
}

const std::vector<sim::Vec3>& World::Impl::surface_now() {
  if (deformed_stale && !sim->empty()) embedding->deformed_positions(sim->state().x, deformed, surface_exec);
  deformed_stale = false;
  return deformed;
}

sim::Pose World::Impl::tool_pose(std::size_t i, double t) const {
  const ToolRuntime& tr = tools.at(i);
  return tr.driven ? *tr.driven : sim::interpolate_pose(tr.keyframes, t);
}

CutSummary World::Impl::cut(std::size_t i, double t, bool scheduled) {
  // The blade where its tool is at the cut's time, through the cut pipeline (a transaction: skipped on failure).
  ensure_blade(i);
  const ToolRuntime& tr = tools[i];
  const sim::Pose pose = tool_pose(i, t);
  cutting::CutRequest req;
  req.blade = *tr.blade;
  for (sim::Vec3& p : req.blade.vertices) p = pose.apply(p);
  req.inscribed_radius = tr.inscribed_radius;
  const cutting::CutOutcome o = cutting::apply_cut(object, *sim, *embedding, req, cut_options);

  CutSummary c;
  c.t = t;
  c.tool = scene.tools[i].name;
  c.status = o.status;
  c.reason = o.reason;
  c.scheduled = scheduled;
  c.components = o.components;
  c.restricted_components = o.restricted_components;
  c.unrestricted_components = o.unrestricted;
  c.removed_volume_m3 = o.removed_volume;
  c.tets_removed = o.tets_removed;
  c.leaves_refined = o.leaves_refined;
  c.fragments_removed = o.fragments_removed;
  c.fragment_volume_m3 = o.fragment_volume;
  c.snapped = o.snapped;
  c.collapses = o.collapses;
  c.new_triangles = o.new_triangles;
  c.min_angle_deg = o.min_angle_deg;
  c.min_edge_m = o.min_edge;
  c.elements_after = sim->model().num_elements();
  c.dofs_after = sim->model().num_dofs();
  c.surface_vertices_after = long(object.surface.num_vertices());
  c.ms = {o.ms.back_transform, o.ms.surface, o.ms.material_graph, o.ms.refine, o.ms.node_split,
          o.ms.embedding,      o.ms.solver_update, o.ms.total};
  c.latency_ms = c.ms.back();
  c.bridge_ms = o.ms.bridge;
  settling.emplace_back(cuts.size(), CutSummary::kSettleSteps);
  cuts.push_back(c);

  // What the report should say about it.
  const std::string what = "cut at t = " + format_seconds(t) + " by " + c.tool;
  if (o.status == "skipped") warnings.push_back(what + " skipped: " + o.reason);
  if (o.perturbed > 0)
    warnings.push_back(what + ": a degenerate blade position was moved by " + format_fraction(o.blade_shift) +
                       " of the blade's size");
  if (o.unrestricted > 0)
    warnings.push_back(what + ": the blade also covered other material in rest space, and could not be kept off it (" +
                       std::to_string(o.unrestricted) + " component(s)): it cut all of it");
  if (o.status == "ok") {
    ++surface_revision;
    surface_changed();
    refresh_samples();  // the new cut faces collide
  }
  return c;
}

void World::Impl::run_due_cuts(std::vector<CutSummary>& out) {
  const double now = sim->state().t;
  while (next_event < events.size() && events[next_event].t <= now + 1e-9 * scene.solver.dt) {
    const CutEvent ev = events[next_event++];
    out.push_back(cut(ev.tool, ev.t, true));
  }
}

void World::Impl::record_counts(Report& r) const {
  // Counts of the current revision and of S.
  const sim::ObjectModel& m = sim->model();
  const sim::TriMesh& surface = object.surface;
  r.object_removed = sim->empty();
  r.elements = m.num_elements();
  r.dofs = m.num_dofs();
  r.hanging_slots = m.dofs().hanging_slots;
  r.tets = sim->empty() || !m.material_graph() ? 0 : m.material_graph()->num_tets();
  r.surface_vertices = long(surface.num_vertices());
  r.surface_triangles = long(surface.num_triangles());
  const sim::SurfaceCheck check = sim::check_surface(surface);
  r.surface_closed = check.closed && check.edge_manifold && check.oriented;
  r.surface_components = check.components;
  // Genus from the Euler characteristic of a closed surface: chi = V - E + F = 2 (components - genus).
  if (r.surface_closed && !surface.triangles.empty()) {
    const long chi = long(surface.num_vertices()) - long(3 * surface.num_triangles() / 2) + long(surface.num_triangles());
    r.surface_genus = (2 * long(check.components) - chi) / 2;
  }
  // S is free of self-intersections: load_mesh rejects a self-intersecting mesh (CGAL, exact predicates), a box
  // grid cannot intersect itself, and every cut checks its changed faces (cutting.verify) or is skipped. With
  // verification off, the whole surface is checked here.
  r.surface_self_intersecting = !scene.cutting.verify && !cuts.empty() && !surface.triangles.empty() &&
                                cutting::find_self_intersection(surface).has_value();
  r.rest_volume_m3 = sim::signed_volume(surface);
}

// True when a handle has a keyframe later than t (s): it moves, or may move, after t and so puts work in.
bool World::Impl::handles_move_after(double t) const {
  for (const Handle& h : scene.object.handles)
    if (!h.keyframes.empty() && h.keyframes.back().t > t) return true;
  return false;
}

void World::Impl::record_state(Report& r) const {
  // Probes, energies and the stability counters of the current state.
  const sim::ObjectModel& m = sim->model();
  for (const Probe& p : scene.probes) {
    const auto e = m.embed(to_vec3(p.point));
    if (!e) {
      r.warnings.push_back("probe " + p.name + ": its point was cut away");
      r.probes.push_back({p.name, p.point, {NAN, NAN, NAN}});
      continue;
    }
    r.probes.push_back({p.name, p.point, a3(sim->position(*e) - to_vec3(p.point))});
  }
  r.finite = state_finite(sim->state());
  const sim::StabilityStats& st = sim->stats();
  r.recoveries = st.recoveries;
  r.failed_steps = st.failed_steps;
  r.solver_failures = st.solver_failures;
  r.nonfinite = st.nonfinite;
  r.speed_limit = st.speed_limit;
  r.energy_rejections = st.energy_rejections;
  r.energy_projections = st.energy_projections;
  r.energy_shortened = st.energy_shortened;
  r.energy_removed_j = st.energy_removed_j;
  r.energy_unremoved_j = st.energy_unremoved_j;
  r.newton_unconverged = st.newton_unconverged;
  r.max_speed_m_s = st.max_speed;
  r.min_volume_ratio = st.min_volume_ratio;
  r.kinetic_j = sim->kinetic_energy();
  r.elastic_j = sim->elastic_energy();
  r.sim_time_s = sim->state().t;
  if (track) r.track = track->result();
  if (st.failed_steps > 0)
    r.warnings.push_back(std::to_string(st.failed_steps) +
                         " steps failed at the smallest dt and were reset (velocities zeroed)");
  if (st.newton_unconverged > 0)
    r.warnings.push_back(std::to_string(st.newton_unconverged) + " static solves stopped unconverged");
}

void World::Impl::record_contact(Report& r) const {
  if (!contact) return;
  ContactSummary& c = r.contact;
  c.present = true;
  c.max_penetration_m = contact->max_penetration();
  c.samples = samples.size();
  c.stiffness_pa_m = contact_stiffness;
  for (const ColliderState& s : contact->colliders()) {
    if (s.kind == ColliderState::Kind::tool) c.tools.push_back({s.name, s.max_force, s.force});
    if (s.kind != ColliderState::Kind::body) continue;
    // XYZ Euler angles of R = Rz Ry Rx.
    const sim::Mat3& R = s.pose.rotation;
    const double deg = 180.0 / M_PI;
    const std::array<double, 3> angles = {std::atan2(R(2, 1), R(2, 2)) * deg,
                                          std::asin(std::clamp(-R(2, 0), -1.0, 1.0)) * deg,
                                          std::atan2(R(1, 0), R(0, 0)) * deg};
    c.bodies.push_back({s.name, a3(s.pose.position), angles, s.velocity, s.force});
  }
}

// ---- World ---------------------------------------------------------------------------------------------------------

World::World(const Scene& scene, const WorldOptions& options) : m(std::make_unique<Impl>(scene, options)) {}
World::~World() = default;
World::World(World&&) noexcept = default;
World& World::operator=(World&&) noexcept = default;

StepResult World::step() {
  const auto t0 = sim::Clock::now();
  StepResult r;
  const double t_start = m->sim->state().t;
  m->run_due_cuts(r.cuts);
  const auto sim0 = sim::Clock::now();
  m->contact_before_step();
  m->sim->step();  // an object cut away entirely only advances time (sim::Simulator::remove_object)
  m->contact_after_step();
  m->surface_changed();
  // The first step after a cut is part of what the cut costs the user (the solver may rebuild after it).
  const double sim_ms = sim::ms_since(sim0);
  for (auto& [c, left] : m->settling) {
    if (left == CutSummary::kSettleSteps) m->cuts[c].latency_ms += sim_ms;
    m->cuts[c].settle_max_ms = std::max(m->cuts[c].settle_max_ms, sim_ms);
    --left;
  }
  std::erase_if(m->settling, [](const auto& s) { return s.second <= 0; });
  m->run_due_cuts(r.cuts);
  if (m->track) m->track->after_step(*m->sim, r.cuts.empty() && !m->handles_move_after(t_start));
  ++m->steps;
  r.t = m->sim->state().t;
  r.ms = sim::ms_since(t0);
  m->step_ms.push_back(r.ms);
  return r;
}

double World::time() const { return m->sim->state().t; }
long World::steps() const { return m->steps; }
long World::total_steps() const { return m->total_steps; }
bool World::done() const { return m->steps >= m->total_steps; }

CutSummary World::cut_now(std::size_t tool) {
  if (tool >= m->tools.size()) throw std::out_of_range("World::cut_now: no tool " + std::to_string(tool));
  return m->cut(tool, time(), false);
}

void World::set_tool_pose(std::size_t tool, const sim::Pose& pose) { m->tools.at(tool).driven = pose; }
void World::release_tool(std::size_t tool) { m->tools.at(tool).driven.reset(); }
void World::hold_tool(std::size_t tool) {
  ToolRuntime& tr = m->tools.at(tool);
  m->ensure_blade(tool);  // a held tool cuts: a bad blade is bad input now, not at the first cut
  tr.driven = m->tool_pose(tool, time());
  const auto first = m->events.begin() + std::ptrdiff_t(m->next_event);
  m->events.erase(std::remove_if(first, m->events.end(), [&](const CutEvent& e) { return e.tool == tool; }),
                  m->events.end());
}

void World::set_material(const Material& edit) {
  Material material = edit;
  if (material.element.empty()) material.element = m->scene.object.material.element;  // unnamed: kept
  const sim::MaterialParams p = material_params(material);  // the element too (checked): B-bar stays B-bar
  // with_params checks the ranges before anything changes; an object cut away has no model to change.
  sim::ObjectModel next = m->sim->model().with_params(p);
  if (!m->sim->empty()) m->sim->set_model(std::move(next));
  m->scene.object.material = material;
}

const Material& World::material() const { return m->scene.object.material; }

void World::set_overlays(const OverlaySettings& overlays) { m->scene.render.overlays = overlays; }

sim::Pose World::tool_pose(std::size_t tool) const { return m->tool_pose(tool, time()); }

std::optional<std::size_t> World::tool_index(const std::string& name) const {
  for (std::size_t i = 0; i < m->scene.tools.size(); ++i)
    if (m->scene.tools[i].name == name) return i;
  return std::nullopt;
}

bool World::has_contact() const { return m->contact != nullptr; }

std::array<double, 3> World::tool_contact_force(std::size_t tool) const {
  if (tool >= m->tools.size()) throw std::out_of_range("World::tool_contact_force: no tool " + std::to_string(tool));
  if (m->contact)
    for (const ColliderState& c : m->contact->colliders())
      if (c.kind == ColliderState::Kind::tool && c.index == tool) return c.force;
  return {0.0, 0.0, 0.0};
}

std::vector<ContactForce> World::contact_forces() const {
  std::vector<ContactForce> out;
  if (!m->contact) return out;
  for (const ColliderState& c : m->contact->colliders())
    if (c.kind != ColliderState::Kind::prop)
      out.push_back({c.name, c.kind == ColliderState::Kind::tool, c.force, c.max_penetration});
  return out;
}

ContactTiming World::contact_timing() const {
  if (!m->contact) return {};
  const ContactProfile& q = m->contact->profile();
  return {q.queries, m->sim->profile().contact, q.rigid, q.searched, q.triangles};
}

double World::rigid_body_energy() const { return m->contact ? m->contact->rigid_energy() : 0.0; }

bool World::renders() const { return m->rendering; }

RenderScene World::render_scene() const {
  if (!m->rendering) throw std::logic_error("World::render_scene: this world does not render");
  const Scene& scene = m->scene;
  const double t = time();
  RenderScene rs;
  rs.width = scene.render.width;
  rs.height = scene.render.height;
  rs.msaa = scene.render.msaa;
  rs.camera = m->camera;
  const sim::ObjectModel& model = m->sim->model();
  std::vector<sim::Vec3> slots;
  model.dofs().prolong(m->sim->state().x, slots);
  if (m->sim->empty()) {
    // Nothing left to draw of the tissue.
  } else if (!model.material_graph()) {
    rs.meshes.push_back(tissue_mesh(model, m->box_tissue, slots));
  } else {
    // The mesh surface S as the Z-curve embedding moved it after the last step, cut faces tinted.
    if (m->crease_revision != m->surface_revision) {
      m->crease = crease_topology(m->object.surface, m->object.cut_faces, scene.render.crease_angle_deg);
      m->crease_revision = m->surface_revision;
    }
    rs.meshes.push_back(crease_mesh(m->crease, m->surface_now(), m->object.cut_faces));
  }
  // Props and tools at their pose now; the camera follows the one it is told to.
  for (std::size_t i = 0; i < m->props.size(); ++i) {
    const sim::Pose pose = sim::interpolate_pose(m->props[i].keyframes, t);
    RenderMesh mesh = m->props[i].mesh;
    mesh.model = pose.matrix().cast<float>();
    mesh.still = m->props[i].keyframes.size() <= 1;  // a fixed pose
    rs.meshes.push_back(std::move(mesh));
    if (scene.render.props[i].name == scene.render.camera.follow_tool) follow_tool(rs.camera, pose.position);
  }
  if (m->contact) {
    for (const ColliderState& c : m->contact->colliders()) {
      if (c.kind != ColliderState::Kind::body || c.index >= m->body_meshes.size() || !m->body_meshes[c.index]) continue;
      RenderMesh mesh = *m->body_meshes[c.index];
      mesh.model = c.pose.matrix().cast<float>();
      rs.meshes.push_back(std::move(mesh));
    }
  }
  for (std::size_t i = 0; i < m->tools.size(); ++i) {
    const sim::Pose pose = m->tool_pose(i, t);
    rs.tool_meshes.push_back(m->tools[i].mesh ? int(rs.meshes.size()) : -1);
    if (m->tools[i].mesh) {
      RenderMesh mesh = *m->tools[i].mesh;
      mesh.model = pose.matrix().cast<float>();
      rs.meshes.push_back(std::move(mesh));
    }
    if (scene.tools[i].name == scene.render.camera.follow_tool) follow_tool(rs.camera, pose.position);
  }
  if (!m->sim->empty()) {
    add_overlays(rs, scene.render.overlays, model, slots, m->sim->state().x);
    add_contact_overlay(rs, scene.render.overlays, m->drawn_contacts, m->sim->contact_outcomes(), m->sim->state().x);
  }
  return rs;
}

Report World::report() const {
  Report r;
  r.scene = m->scene.file;
  r.name = m->scene.name;
  r.steps = m->steps;
  r.step_ms = TimingSummary::of(m->step_ms);
  double stepping_ms = 0.0;
  for (double ms : m->step_ms) stepping_ms += ms;
  r.realtime_factor = stepping_ms > 0.0 ? m->sim->state().t / (stepping_ms / 1000.0) : 0.0;
  r.warnings = m->warnings;
  r.cuts = m->cuts;
  r.subsystems.cut_index = m->object.grid.grid != nullptr;
  r.subsystems.material_graph = to_string(m->graph_source);
  r.subsystems.contact = m->contact != nullptr;
  m->record_counts(r);
  m->record_state(r);
  m->record_contact(r);
  return r;
}

const Scene& World::scene() const { return m->scene; }
const sim::Simulator& World::simulator() const { return *m->sim; }
const sim::TriMesh& World::rest_surface() const { return m->object.surface; }
const std::vector<sim::Vec3>& World::deformed_vertices() const { return m->surface_now(); }
sim::TriMesh World::deformed_surface() const { return sim::TriMesh{m->surface_now(), m->object.surface.triangles}; }
bool World::object_removed() const { return m->sim->empty(); }

}  // namespace octocut::engine
