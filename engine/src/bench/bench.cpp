#include "octocut/engine/bench/bench.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <cstdio>
#include <cmath>
#include <ctime>
#include <fstream>
#include <numbers>
#include <numeric>
#include <functional>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <system_error>
#include <thread>
#include <vector>

#include "octocut/engine/io/material_graph_cache.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/sim/material_graph.hpp"
#include "octocut/engine/bench/embedding_bench.hpp"
#include "octocut/engine/render/frame_writer.hpp"
#include "octocut/engine/render/renderer.hpp"
#include "octocut/sim/simulator.hpp"
#include "octocut/sim/surface.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/run/report.hpp"
#include "octocut/sim/timing.hpp"
#include <unistd.h>

namespace octocut::engine {

namespace {

using sim::Clock;
using json = nlohmann::ordered_json;

struct BenchOutput {
  std::string name;
  long runs = 0;
  TimingSummary ms;
  json params = json::object();
  json metrics = json::object();
};

// The step benchmark of issue 2: a 1 cm cube of 10 x 10 x 10 leaves (E = 5e4 Pa, nu = 0.45, rho = 1000 kg/m^3),
// bottom fixed, under gravity, dt = 1 ms; trilinear hexahedra unless `element` says otherwise.
sim::ObjectModel cube10(sim::HexFormulation element = sim::HexFormulation::trilinear) {
  sim::OctreeSpec spec;
  spec.root = {sim::Vec3::Zero(), 0.016};  // level 4 cells are 1 mm
  spec.base_level = 4;
  spec.max_level = 8;
  sim::MaterialParams p;
  p.young_modulus = 5e4;
  p.poisson_ratio = 0.45;
  p.density = 1000.0;
  p.element = element;
  sim::HandleSpec bottom{{sim::Vec3(-0.001, -0.001, -0.001), sim::Vec3(0.011, 0.011, 1e-9)}, {}};
  return sim::ObjectModel::build(spec, std::make_shared<sim::BoxMaterial>(sim::Box3{sim::Vec3::Zero(), sim::Vec3::Constant(0.01)}),
                                 p, {bottom});
}

struct StepRun {
  std::vector<double> step_ms;
  std::vector<sim::Vec3> probe;  // displacement of the top-centre probe after each step, m
  std::vector<sim::StepProfile> profile;
  long iterations = 0, refactorizations = 0;
  sim::StabilityStats stats;
};

StepRun run_cube(const std::string& solver, const std::string& preconditioner, double tolerance, int steps,
                 int threads, sim::HexFormulation element = sim::HexFormulation::trilinear) {
  sim::SimulatorOptions o;
  o.dt = 1e-3;
  o.linear_solver = solver;
  o.preconditioner = preconditioner;
  o.tolerance = tolerance;
  o.threads = threads;
  sim::Simulator s(cube10(element), o);
  const sim::Vec3 top(0.005, 0.005, 0.01);
  const auto e = *s.model().embed(top);
  StepRun r;
  for (int i = 0; i < steps; ++i) {
    const auto t0 = Clock::now();
    s.step();
    r.step_ms.push_back(sim::ms_since(t0));
    r.probe.push_back(s.position(e) - top);
    r.profile.push_back(s.profile());
    r.iterations += s.last_solve().iterations;
    r.refactorizations += s.last_solve().refactorized ? 1 : 0;
  }
  r.stats = s.stats();
  return r;
}

double median_of(std::vector<double> v) { return TimingSummary::of(std::move(v)).median; }

// The median of one part of the step profile (ms) over the steps from `skip` on.
double profile_median(const std::vector<sim::StepProfile>& profile, std::size_t skip, double sim::StepProfile::*part) {
  std::vector<double> ms;
  for (std::size_t i = skip; i < profile.size(); ++i) ms.push_back(profile[i].*part);
  return median_of(std::move(ms));
}

// A file under assets/: $OCTOCUT_ASSET_DIR, else the source tree's assets/ folder.
std::filesystem::path asset_path(const std::string& relative) {
  const char* dir = std::getenv("OCTOCUT_ASSET_DIR");
  return std::filesystem::path(dir && *dir ? dir : OCTOCUT_ASSET_DIR) / relative;
}

std::vector<BenchOutput> bench_step(const std::string& variant) {
  const int steps = 400;
  const int threads = 0;
  // cube10-bbar: the cube10 case with B-bar hexahedra (issue 17 §3), its reference B-bar too.
  const sim::HexFormulation element =
      variant == "cube10-bbar" ? sim::HexFormulation::bbar : sim::HexFormulation::trilinear;
  // The exact reference: CHOLMOD factorises and solves every step.
  const StepRun ref = run_cube("cholmod", "cholesky", 1e-12, steps, threads, element);
  StepRun run;
  if (variant == "cube10" || variant == "cube10-bbar")
    run = run_cube("pcg", "cholesky", 1e-3, steps, threads, element);
  else if (variant == "cube10-jacobi")
    run = run_cube("pcg", "jacobi", 1e-4, steps, threads);
  else
    run = ref;

  // Relative probe error: the largest deviation from the exact run over the whole run, over the largest exact
  // displacement.
  double max_dev = 0.0, max_ref = 0.0;
  for (std::size_t i = 0; i < ref.probe.size(); ++i) {
    max_dev = std::max(max_dev, (run.probe[i] - ref.probe[i]).norm());
    max_ref = std::max(max_ref, ref.probe[i].norm());
  }
  const sim::ObjectModel m = cube10(element);
  BenchOutput b;
  b.name = "step/" + variant;
  // The first steps include the symbolic analysis and the first factorisation: report steady state.
  const std::vector<double> steady(run.step_ms.begin() + 10, run.step_ms.end());
  b.runs = long(steady.size());
  b.ms = TimingSummary::of(steady);
  const std::string solver = variant == "cube10-cholmod" ? "cholmod" : "pcg";
  const std::string pre = variant == "cube10-jacobi" ? "jacobi" : (solver == "pcg" ? "cholesky" : "none");
  b.params = {{"leaves", "10x10x10"}, {"edge_m", 0.01}, {"young_modulus_pa", 5e4}, {"poisson_ratio", 0.45},
              {"density_kg_m3", 1000.0}, {"dt_s", 1e-3}, {"steps", steps}, {"linear_solver", solver},
              {"preconditioner", pre}, {"threads", int(std::thread::hardware_concurrency())},
              {"element", element == sim::HexFormulation::bbar ? "bbar" : "trilinear"}};
  b.metrics = {{"elements", m.num_elements()},
               {"dofs", m.num_dofs()},
               {"rel_error_vs_exact", max_ref > 0 ? max_dev / max_ref : 0.0},
               {"rotations_ms", profile_median(run.profile, 10, &sim::StepProfile::rotations)},
               {"forces_ms", profile_median(run.profile, 10, &sim::StepProfile::forces)},
               {"assembly_ms", profile_median(run.profile, 10, &sim::StepProfile::assembly)},
               {"solve_ms", profile_median(run.profile, 10, &sim::StepProfile::solve)},
               {"mean_pcg_iterations", double(run.iterations) / steps},
               {"refactorizations", run.refactorizations},
               {"recoveries", run.stats.recoveries}};
  return {b};
}

// Generating the material graph M of the 10k meniscus at 1 mm (SPEC §2.2): cold (Mesh_3 every run, no cache) and
// from the disk cache, plus building the level-5 octree on M (occupancy by tet clipping, connectivity, DOFs).
std::vector<BenchOutput> bench_material_graph() {
  const std::filesystem::path file = asset_path("meshes/meniscus_10k.ply");
  const sim::TriMesh surface = load_mesh(file, MeshLoadOptions{0.001, true, false}).mesh;
  const double h = 0.001;
  std::vector<double> cold, cached, octree;
  sim::TetMesh tets;
  for (int i = 0; i < 3; ++i) {
    const MaterialGraphResult r = material_graph_for(surface, h, false);
    cold.push_back(r.ms);
    tets = r.mesh;
  }
  // One run fills the cache; the timed runs read it.
  material_graph_for(surface, h, true);
  for (int i = 0; i < 10; ++i) {
    const MaterialGraphResult r = material_graph_for(surface, h, true);
    if (!r.from_cache) throw std::runtime_error("material_graph bench: the cache entry was not used: " + r.warning);
    cached.push_back(r.ms);
  }
  const auto graph = std::make_shared<sim::MaterialGraph>(tets);
  const sim::Box3 b = sim::bounds(surface);
  const double size = 1.05 * (b.max - b.min).maxCoeff();
  sim::OctreeSpec spec;
  spec.root = {0.5 * (b.min + b.max) - sim::Vec3::Constant(0.5 * size), size};
  spec.base_level = 5;
  spec.max_level = 8;
  int elements = 0;
  for (int i = 0; i < 3; ++i) {
    const auto t0 = Clock::now();
    const sim::ObjectModel m = sim::ObjectModel::build(spec, graph, {}, {});
    octree.push_back(sim::ms_since(t0));
    elements = m.num_elements();
  }
  BenchOutput out;
  out.name = "material_graph/meniscus10k";
  out.runs = long(cold.size());
  out.ms = TimingSummary::of(cold);
  out.params = {{"surface", "assets/meshes/meniscus_10k.ply"}, {"cell_size_m", h}, {"octree_level", 5}};
  out.metrics = {{"cold_ms", median_of(cold)},
                 {"cached_ms", median_of(cached)},
                 {"tets", graph->num_tets()},
                 {"tet_volume_m3", graph->volume()},
                 {"surface_volume_m3", sim::signed_volume(surface)},
                 {"octree_build_ms", median_of(octree)},
                 {"elements", elements}};
  return {out};
}

// The 10k meniscus (m) and its material graph at 1 mm, loaded once per process.
struct MeniscusInput {
  sim::TriMesh surface;
  std::shared_ptr<const sim::MaterialGraph> graph;
};
const MeniscusInput& meniscus10k() {
  static const MeniscusInput in = [] {
    MeniscusInput m;
    m.surface = load_mesh(asset_path("meshes/meniscus_10k.ply"), MeshLoadOptions{0.001, true, false}).mesh;
    m.graph = std::make_shared<sim::MaterialGraph>(material_graph_for(m.surface, 0.001).mesh);
    return m;
  }();
  return in;
}

// Paper Fig. 6: correspondence update after a 100-vertex cut, Z-curve list against per-level lists, at one depth.
std::vector<BenchOutput> bench_embedding(int depth) {
  EmbeddingBenchOptions o;
  o.min_depth = o.max_depth = depth;
  const MeniscusInput& in = meniscus10k();
  const EmbeddingBenchResult r = run_embedding_bench(in.surface, *in.graph, o).front();
  BenchOutput b;
  b.name = "embedding/depth" + std::to_string(depth);
  b.runs = long(r.zcurve_ms.size());
  b.ms = TimingSummary::of(r.zcurve_ms);
  b.params = {{"mesh", "assets/meshes/meniscus_10k.ply"}, {"material", "material graph, cell 1 mm"},
              {"depth", depth},
              {"leaves", r.leaves},
              {"naive_nodes", r.naive_nodes},
              {"removed", r.removed},
              {"ball_radius_m", o.ball_radius},
              {"inserted_fallback", r.fallback}};
  b.metrics = {{"zcurve_ms", median_of(r.zcurve_ms)},
               {"naive_ms", median_of(r.naive_ms)},
               {"vertices", r.vertices},
               {"inserted", r.inserted}};
  return {b};
}

// ---- render/1280x720: render and PNG encode time per frame (SPEC §7) --------------------------------------------

// Renders `mesh` as tissue at 1280 x 720 (4x MSAA, a light at the lens) from 30 slightly different views and
// PNG-encodes every frame as the frame writer does (level 1, no filter; the sub filter as a comparison). The same views with 2
// samples and with 1 sample per pixel are timed too. Besides wall time, the process CPU time per frame (all
// threads, llvmpipe's workers included) is reported: contention on a shared machine inflates it less.
BenchOutput bench_render_mesh(const std::string& label, const sim::TriMesh& mesh) {
  const int width = 1280, height = 720, frames = 30;
  std::unique_ptr<Renderer> renderer = make_renderer();
  RenderScene scene;
  scene.width = width;
  scene.height = height;
  RenderMesh tissue;
  for (const sim::Vec3& v : mesh.vertices) tissue.positions.push_back(v.cast<float>());
  tissue.triangles = mesh.triangles;
  tissue.normals = mesh_normals(tissue.positions, tissue.triangles);
  scene.meshes.push_back(std::move(tissue));
  const sim::Box3 box = sim::bounds(mesh);
  const Eigen::Vector3d centre = 0.5 * (box.min + box.max);
  const double radius = 0.5 * (box.max - box.min).norm();
  scene.camera.target = centre;
  scene.camera.fov_deg = 60.0;
  scene.camera.near = 1e-3 * radius;
  scene.camera.far = 10.0 * radius;
  scene.camera.arthroscope = true;
  const auto cpu_ms = [] { return 1000.0 * double(std::clock()) / CLOCKS_PER_SEC; };

  // One pass over the views at `msaa` samples: wall ms per frame, CPU ms per frame (mean), and the images encoded
  // when `encode` is set.
  std::vector<double> encode_ms, encode_sub_ms;
  std::size_t png_bytes = 0;
  const auto pass = [&](int msaa, bool encode, std::vector<double>& wall, double& cpu) {
    scene.msaa = msaa;
    // Warm up: shader compilation, framebuffers for this sample count.
    scene.camera.position = centre + Eigen::Vector3d(0.0, -2.0 * radius, 1.2 * radius);
    renderer->render(scene);
    double cpu_total = 0.0;
    for (int f = 0; f < frames; ++f) {
      const double angle = 0.02 * f;
      scene.camera.position =
          centre + Eigen::Vector3d(2.0 * radius * std::sin(angle), -2.0 * radius * std::cos(angle), 1.2 * radius);
      const double c0 = cpu_ms();
      auto t0 = Clock::now();
      const Image image = renderer->render(scene);
      wall.push_back(sim::ms_since(t0));
      cpu_total += cpu_ms() - c0;
      if (!encode) continue;
      t0 = Clock::now();
      png_bytes = encode_png(image, 1, false).size();
      encode_ms.push_back(sim::ms_since(t0));
      t0 = Clock::now();
      (void)encode_png(image, 1, true);
      encode_sub_ms.push_back(sim::ms_since(t0));
    }
    cpu = cpu_total / frames;
  };
  std::vector<double> render_ms, msaa2_ms, msaa1_ms;
  double render_cpu = 0.0, msaa2_cpu = 0.0, msaa1_cpu = 0.0;
  pass(4, true, render_ms, render_cpu);
  pass(2, false, msaa2_ms, msaa2_cpu);
  pass(1, false, msaa1_ms, msaa1_cpu);

  BenchOutput b;
  b.name = "render/1280x720/" + label;
  b.runs = frames;
  b.ms = TimingSummary::of(render_ms);
  b.params = {{"width", width}, {"height", height}, {"msaa", 4}, {"mesh", label},
              {"vertices", mesh.num_vertices()}, {"triangles", mesh.num_triangles()},
              {"renderer", renderer->description()}, {"png", "zlib level 1, no filter"}};
  b.metrics = {{"render_ms", median_of(render_ms)},
               {"render_p95_ms", TimingSummary::of(render_ms).p95},
               {"render_cpu_ms", render_cpu},
               {"render_msaa2_ms", median_of(msaa2_ms)},
               {"render_msaa2_cpu_ms", msaa2_cpu},
               {"render_msaa1_ms", median_of(msaa1_ms)},
               {"render_msaa1_cpu_ms", msaa1_cpu},
               {"encode_ms", median_of(encode_ms)},
               {"encode_sub_filter_ms", median_of(encode_sub_ms)},
               {"png_bytes", png_bytes}};
  return b;
}

std::vector<BenchOutput> bench_render() {
  // The shipped meniscus surfaces, in metres.
  const MeshLoadOptions mm{0.001, true, false};
  return {bench_render_mesh("10k", load_mesh(asset_path("meshes/meniscus_10k.ply"), mm).mesh),
          bench_render_mesh("50k", load_mesh(asset_path("meshes/meniscus_50k.ply"), mm).mesh)};
}

// ---- render/meniscus_punch: the frame of the shipped scene (issue 20, item 4) ------------------------------------

// The meniscus_punch scene's own frame (1280 x 720, 4x MSAA, arthroscope light and mask, the meniscus with its
// crease-split normals, femoral condyle, tibial plateau and the punch) at t = 0 and after 0.3 s (150 steps, the
// punch in view), each drawn 15 times by a renderer on this thread with nothing else running: wall and process CPU
// time per frame.
std::vector<BenchOutput> bench_render_scene() {
  const Scene scene = load_scene(asset_path("scenes/meniscus_punch.json"));
  World world(scene, WorldOptions{true});
  std::unique_ptr<Renderer> renderer = make_renderer();
  const auto cpu_ms = [] { return 1000.0 * double(std::clock()) / CLOCKS_PER_SEC; };
  std::vector<double> wall, cpu;
  for (const long steps : {0L, 150L}) {
    while (world.steps() < steps && !world.done()) world.step();
    const RenderScene snapshot = world.render_scene();
    renderer->render(snapshot);  // warm up: shader variants, framebuffers
    for (int f = 0; f < 15; ++f) {
      const double c0 = cpu_ms();
      const auto t0 = Clock::now();
      renderer->render(snapshot);
      wall.push_back(sim::ms_since(t0));
      cpu.push_back(cpu_ms() - c0);
    }
  }
  BenchOutput b;
  b.name = "render/meniscus_punch";
  b.runs = int(wall.size());
  b.ms = TimingSummary::of(wall);
  b.params = {{"width", scene.render.width}, {"height", scene.render.height}, {"msaa", scene.render.msaa},
              {"renderer", renderer->description()}, {"frames", "t = 0 and t = 0.3 s, 15 each"}};
  b.metrics = {{"render_ms", median_of(wall)}, {"render_p95_ms", TimingSummary::of(wall).p95},
               {"render_cpu_ms", median_of(cpu)}};
  return {b};
}

// ---- cut/<scene>: the stages of every cut of a shipped cutting scene (SPEC §7) ------------------------------------

// Runs the scene's World without rendering and without writing anything, and reports the median of each stage over
// its ok cuts; `total` is the whole cut.
std::vector<BenchOutput> bench_cut(const std::string& scene_name) {
  const std::string file = asset_path("scenes/" + scene_name + ".json");
  const Scene scene = load_scene(file);
  World world(scene, WorldOptions{false});
  while (!world.done()) world.step();
  // From the report, where each cut's latency_ms includes the first step after it.
  const std::vector<CutSummary> cuts = world.report().cuts;
  std::array<std::vector<double>, kCutStageKeys.size()> stage;
  std::vector<double> latency, bridge;
  int ok = 0, skipped = 0, noop = 0;
  for (const CutSummary& c : cuts) {
    if (c.status == "ok") {
      ++ok;
      for (std::size_t k = 0; k < kCutStageKeys.size(); ++k) stage[k].push_back(c.ms[k]);
      latency.push_back(c.latency_ms);
      bridge.push_back(c.bridge_ms);
    } else if (c.status == "skipped") {
      ++skipped;
    } else {
      ++noop;
    }
  }
  BenchOutput b;
  b.name = "cut/" + scene_name;
  b.runs = ok;
  b.ms = TimingSummary::of(stage.back());
  b.params = {{"scene", "assets/scenes/" + scene_name + ".json"}, {"cuts", cuts.size()}, {"ok", ok},
              {"skipped", skipped}, {"no_op", noop}, {"threads", int(std::thread::hardware_concurrency())}};
  for (std::size_t k = 0; k < kCutStageKeys.size(); ++k)
    b.metrics[std::string(kCutStageKeys[k]) + "_ms"] = median_of(stage[k]);
  b.metrics["latency_ms"] = median_of(latency);  // the cut plus the first step after it
  b.metrics["bridge_ms"] = median_of(bridge);    // the first step's work the model thread did ahead of it
  if (!cuts.empty()) {
    b.metrics["elements_after"] = cuts.back().elements_after;
    b.metrics["surface_vertices_after"] = cuts.back().surface_vertices_after;
  }
  return {b};
}

// ---- step/<scene>, scaling, latency/<scene>: the shipped scenes at their own settings (real-time issue) ----------

// One run of a scene through World without rendering: every step's wall time and profile, PCG iterations and
// refactorisations, and the DOF positions after every step (for the error against an exact run of the same model).
struct SceneStepRun {
  std::vector<double> step_ms;
  std::vector<sim::StepProfile> profile;
  std::vector<std::vector<sim::Vec3>> x;  // DOF positions after each step (steps x num_dofs, m)
  std::vector<sim::Vec3> x0;              // DOF positions at rest (num_dofs, m)
  long iterations = 0, refactorizations = 0, background = 0, elements = 0, dofs = 0;  // background: refreshes
  std::vector<CutSummary> cuts;
  double sim_time_s = 0.0, wall_ms = 0.0;
};

SceneStepRun run_scene_steps(const Scene& scene, bool keep_positions) {
  World world(scene, WorldOptions{false});
  SceneStepRun r;
  r.x0 = world.simulator().state().x;
  r.elements = world.simulator().model().num_elements();
  r.dofs = world.simulator().model().num_dofs();
  const auto t0 = Clock::now();
  while (!world.done()) {
    StepResult step = world.step();
    r.step_ms.push_back(step.ms);
    r.profile.push_back(world.simulator().profile());
    r.iterations += world.simulator().last_solve().iterations;
    r.refactorizations += world.simulator().last_solve().refactorized ? 1 : 0;
    r.background += world.simulator().last_solve().background ? 1 : 0;
    if (keep_positions) r.x.push_back(world.simulator().state().x);
  }
  r.wall_ms = sim::ms_since(t0);
  r.sim_time_s = world.time();
  // From the report: a step's own copy of a cut does not yet hold the first step after it in latency_ms.
  r.cuts = world.report().cuts;
  return r;
}

// The largest DOF deviation of `run` from `exact` over all steps, over the largest exact displacement.
double rel_error(const SceneStepRun& run, const SceneStepRun& exact) {
  double dev = 0.0, ref = 0.0;
  for (std::size_t i = 0; i < exact.x.size() && i < run.x.size(); ++i)
    for (std::size_t d = 0; d < exact.x[i].size() && d < run.x[i].size() && d < exact.x0.size(); ++d) {
      dev = std::max(dev, (run.x[i][d] - exact.x[i][d]).norm());
      ref = std::max(ref, (exact.x[i][d] - exact.x0[d]).norm());
    }
  return ref > 0.0 ? dev / ref : 0.0;
}

// Step time of a shipped scene at its own settings (sets: scene overrides, e.g. a finer base level), with the error
// against the same scene solved exactly (CHOLMOD every step) and where the time goes.
std::vector<BenchOutput> bench_scene_step(const std::string& name, const std::string& scene_name,
                                          const std::vector<std::string>& sets) {
  const std::string file = asset_path("scenes/" + scene_name + ".json");
  const Scene scene = load_scene(file, sets);
  const SceneStepRun run = run_scene_steps(scene, true);
  std::vector<std::string> exact_sets = sets;
  exact_sets.push_back("/solver/linear_solver=cholmod");
  const SceneStepRun exact = run_scene_steps(load_scene(file, exact_sets), true);
  BenchOutput b;
  b.name = name;
  // The first steps include the symbolic analysis and the first factorisation: report steady state.
  const std::size_t skip = std::min<std::size_t>(10, run.step_ms.size() / 10);
  const std::vector<double> steady(run.step_ms.begin() + long(skip), run.step_ms.end());
  b.runs = long(steady.size());
  b.ms = TimingSummary::of(steady);
  b.params = {{"scene", "assets/scenes/" + scene_name + ".json"}, {"sets", sets}, {"dt_s", scene.solver.dt},
              {"linear_solver", scene.solver.linear_solver}, {"tolerance", scene.solver.tolerance},
              {"steps", run.step_ms.size()}, {"threads", int(std::thread::hardware_concurrency())}};
  const double steps = double(std::max<std::size_t>(1, run.step_ms.size()));
  b.metrics = {{"elements", run.elements},
               {"dofs", run.dofs},
               {"rel_error_vs_exact", rel_error(run, exact)},
               {"p95_over_median", b.ms.median > 0 ? b.ms.p95 / b.ms.median : 0.0},
               {"rotations_ms", profile_median(run.profile, skip, &sim::StepProfile::rotations)},
               {"forces_ms", profile_median(run.profile, skip, &sim::StepProfile::forces)},
               {"assembly_ms", profile_median(run.profile, skip, &sim::StepProfile::assembly)},
               {"solve_ms", profile_median(run.profile, skip, &sim::StepProfile::solve)},
               {"mean_pcg_iterations", double(run.iterations) / steps},
               {"refactorizations", run.refactorizations},
               {"background_refreshes", run.background},
               {"realtime_factor", run.wall_ms > 0 ? run.sim_time_s / (run.wall_ms / 1000.0) : 0.0}};
  return {b};
}

// Step time against elements: a soft cube (E = 5e4 Pa, nu = 0.45, 1 mm leaves, bottom clamped, gravity, dt = 1 ms,
// the step benchmark's tolerance 1e-4) from 10^3 to 31^3 leaves, 40 steps each after 5 to warm up.
std::vector<BenchOutput> bench_scaling() {
  std::vector<BenchOutput> out;
  for (const int n : {10, 14, 18, 22, 26, 31}) {
    const double h = 0.001, edge = n * h;
    char text[1024];
    std::snprintf(text, sizeof(text), R"({"name": "scaling %d", "duration": 0.045,
      "solver": {"dt": 0.001, "linear_solver": "pcg", "tolerance": 1e-4},
      "object": {"surface": {"box": {"min": [0, 0, 0], "max": [%.6f, %.6f, %.6f]}},
                 "material": {"young_modulus": 5e4, "poisson_ratio": 0.45, "density": 1000},
                 "octree": {"root": {"min": [0, 0, 0], "size": 0.032}, "base_level": 5, "max_level": 5},
                 "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 1e-9]}}]}})",
                  n, edge, edge, edge);
    const std::filesystem::path dir = std::filesystem::temp_directory_path() / "octocut_bench_scaling";
    std::filesystem::create_directories(dir);
    const std::filesystem::path file = dir / ("cube" + std::to_string(n) + ".json");
    { std::ofstream(file) << text; }
    const SceneStepRun run = run_scene_steps(load_scene(file.string()), false);
    std::filesystem::remove(file);
    BenchOutput b;
    b.name = "scaling/cube" + std::to_string(n);
    const std::vector<double> steady(run.step_ms.begin() + 5, run.step_ms.end());
    b.runs = long(steady.size());
    b.ms = TimingSummary::of(steady);
    b.params = {{"leaves", std::to_string(n) + "^3"}, {"leaf_m", h}, {"young_modulus_pa", 5e4}, {"poisson_ratio", 0.45},
                {"dt_s", 1e-3}, {"tolerance", 1e-4}, {"threads", int(std::thread::hardware_concurrency())}};
    b.metrics = {{"elements", run.elements}, {"dofs", run.dofs},
                 {"ms_per_element_us", 1000.0 * b.ms.median / double(std::max(1L, run.elements))},
                 {"mean_pcg_iterations", double(run.iterations) / double(std::max<std::size_t>(1, run.step_ms.size()))},
                 {"refactorizations", run.refactorizations},
                 {"rotations_ms", profile_median(run.profile, 5, &sim::StepProfile::rotations)},
                 {"forces_ms", profile_median(run.profile, 5, &sim::StepProfile::forces)},
                 {"assembly_ms", profile_median(run.profile, 5, &sim::StepProfile::assembly)},
                 {"solve_ms", profile_median(run.profile, 5, &sim::StepProfile::solve)}};
    out.push_back(std::move(b));
  }
  return out;
}

// What a cut costs the user in a shipped scene: cuts[].latency_ms (the cut plus the first step after it), and the
// longest step after a cut against the median step.
std::vector<BenchOutput> bench_latency(const std::string& scene_name) {
  const std::string file = asset_path("scenes/" + scene_name + ".json");
  const SceneStepRun run = run_scene_steps(load_scene(file), false);
  std::vector<double> latency;
  double settle_max = 0.0;  // ms, the longest step after any cut
  for (const CutSummary& c : run.cuts) {
    latency.push_back(c.latency_ms);
    settle_max = std::max(settle_max, c.settle_max_ms);
  }
  BenchOutput b;
  b.name = "latency/" + scene_name;
  b.runs = long(latency.size());
  b.ms = TimingSummary::of(latency);
  const TimingSummary steps = TimingSummary::of(run.step_ms);
  b.params = {{"scene", "assets/scenes/" + scene_name + ".json"}, {"cuts", run.cuts.size()},
              {"threads", int(std::thread::hardware_concurrency())}};
  b.metrics = {{"latency_median_ms", b.ms.median}, {"latency_p95_ms", b.ms.p95}, {"step_median_ms", steps.median},
               {"step_max_ms", steps.max}, {"settle_max_ms", settle_max},
               {"settle_max_over_step_median", steps.median > 0.0 ? settle_max / steps.median : 0.0},
               {"elements", run.elements}, {"dofs", run.dofs},
               {"realtime_factor", run.wall_ms > 0 ? run.sim_time_s / (run.wall_ms / 1000.0) : 0.0}};
  return {b};
}

// Median step time of meniscus_punch over its whole timeline (3.5 s: the settling onto the tibia, the punch pushing
// the rim and six bites), as shipped (the punch colliding, the bones static colliders) and with nothing colliding,
// and where the contact run's time goes.
std::vector<BenchOutput> bench_contact() {
  const std::string file = asset_path("scenes/meniscus_punch.json");
  const std::vector<std::string> base = {};
  std::vector<std::string> off = base;
  for (const char* k : {"/tools/0/collide=false", "/render/props/0/collide=false", "/render/props/1/collide=false"})
    off.push_back(k);
  auto run = [&](const std::vector<std::string>& sets, json& parts) {
    World world(load_scene(file, sets), WorldOptions{false});
    std::vector<double> step, queries, terms, rigid, assembly, solve;
    long iterations = 0, refactorizations = 0, box_queries = 0, triangles = 0;
    while (!world.done()) {
      step.push_back(world.step().ms);
      iterations += world.simulator().last_solve().iterations;
      refactorizations += world.simulator().last_solve().refactorized ? 1 : 0;
      const ContactTiming c = world.contact_timing();
      queries.push_back(c.queries);
      terms.push_back(c.terms);
      rigid.push_back(c.rigid);
      box_queries += c.box_queries;
      triangles += c.triangles;
      assembly.push_back(world.simulator().profile().assembly);
      solve.push_back(world.simulator().profile().solve);
    }
    parts = {{"queries_ms", median_of(queries)}, {"contact_terms_ms", median_of(terms)},
             {"rigid_ms", median_of(rigid)}, {"assembly_ms", median_of(assembly)}, {"solve_ms", median_of(solve)},
             {"mean_pcg_iterations", double(iterations) / double(std::max<std::size_t>(1, step.size()))},
             {"refactorizations", refactorizations},
             // Bullet's box queries of triangle meshes over the run and the triangles each tested on average (the
             // certified samples' candidates counted too): a BVH whose boxes are too loose shows here.
             {"box_queries", box_queries},
             {"triangles_per_box_query", double(triangles) / double(std::max(1L, box_queries))},
             // The mean decides the real-time factor (simulated over stepping time), the median the overhead below.
             {"mean_step_ms",
              std::accumulate(step.begin(), step.end(), 0.0) / double(std::max<std::size_t>(1, step.size()))}};
    return std::make_pair(TimingSummary::of(step), long(step.size()));
  };
  json parts_off, parts_on;
  const auto [without, n] = run(off, parts_off);
  const auto [with, n_on] = run(base, parts_on);
  BenchOutput b;
  b.name = "contact/meniscus_punch";
  b.runs = n_on;
  b.ms = with;
  b.params = {{"scene", "assets/scenes/meniscus_punch.json"}, {"duration_s", 3.5},
              {"threads", int(std::thread::hardware_concurrency())}};
  b.metrics = {{"median_step_ms", with.median}, {"median_step_without_contact_ms", without.median},
               {"overhead", with.median / without.median - 1.0},
               {"mean_overhead",
                parts_on["mean_step_ms"].get<double>() / parts_off["mean_step_ms"].get<double>() - 1.0},
               {"with_contact", parts_on},
               {"without_contact", parts_off}};
  return {b};
}

struct Entry {
  std::string name;
  std::function<std::vector<BenchOutput>()> run;
};

std::vector<Entry> registry() {
  return {{"step/cube10", [] { return bench_step("cube10"); }},
          {"step/cube10-jacobi", [] { return bench_step("cube10-jacobi"); }},
          {"step/cube10-cholmod", [] { return bench_step("cube10-cholmod"); }},
          {"step/cube10-bbar", [] { return bench_step("cube10-bbar"); }},
          {"material_graph/meniscus10k", [] { return bench_material_graph(); }},
          {"embedding/depth3", [] { return bench_embedding(3); }},
          {"embedding/depth4", [] { return bench_embedding(4); }},
          {"embedding/depth5", [] { return bench_embedding(5); }},
          {"embedding/depth6", [] { return bench_embedding(6); }},
          {"embedding/depth7", [] { return bench_embedding(7); }},
          {"embedding/depth8", [] { return bench_embedding(8); }},
          {"render/1280x720", [] { return bench_render(); }},
          {"render/meniscus_punch", [] { return bench_render_scene(); }},
          {"cut/meniscus_punch", [] { return bench_cut("meniscus_punch"); }},
          {"cut/meniscus_punch_hd", [] { return bench_cut("meniscus_punch_hd"); }},
          {"cut/adaptive_cut", [] { return bench_cut("adaptive_cut"); }},
          {"cut/uniform_cut", [] { return bench_cut("uniform_cut"); }},
          {"cut/meniscus_bites", [] { return bench_cut("meniscus_bites"); }},
          {"cut/meniscus_bites_hd", [] { return bench_cut("meniscus_bites_hd"); }},
          {"cut/slab_punch_20", [] { return bench_cut("slab_punch_20"); }},
          {"step/meniscus_rest", [] { return bench_scene_step("step/meniscus_rest", "meniscus_rest", {}); }},
          {"step/meniscus_l6",
           [] { return bench_scene_step("step/meniscus_l6", "meniscus_rest", {"/object/octree/base_level=6"}); }},
          {"scaling", [] { return bench_scaling(); }},
          {"latency/meniscus_punch", [] { return bench_latency("meniscus_punch"); }},
          {"latency/meniscus_punch_hd", [] { return bench_latency("meniscus_punch_hd"); }},
          {"contact/meniscus_punch", [] { return bench_contact(); }}};
}

}  // namespace

std::string cpu_name() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto c = line.find(':');
      if (c != std::string::npos) return line.substr(c + 2);
    }
  }
  return "unknown";
}

namespace {

}  // namespace

namespace {

// xorshift64: the calibration kernel's pseudo-random numbers (the same on every machine).
uint64_t xorshift64(uint64_t& state) {
  state ^= state << 13;
  state ^= state >> 7;
  state ^= state << 17;
  return state;
}

}  // namespace

CalibrationSample calibration_kernel() {
  // The table for the gathers stays allocated between runs: the kernel measures memory access, not page faults.
  static const std::vector<uint32_t> table = [] {
    std::vector<uint32_t> t(std::size_t(1) << 22);  // 16 MiB
    uint64_t s = 0x2545f4914f6cdd1dull;
    for (uint32_t& x : t) x = static_cast<uint32_t>(xorshift64(s) >> 32);
    return t;
  }();
  const auto t0 = Clock::now();
  uint64_t state = 0x853c49e6748fea9bull;
  const auto next = [&state] { return xorshift64(state); };
  const auto unit = [&next] { return static_cast<double>(next() >> 11) * 0x1.0p-53; };
  uint64_t checksum = 0;
  // 1. Orientation tests of random point quadruples (floating point, unpredictable branches): 2^18 of them.
  std::vector<std::array<double, 3>> points(4096);  // m, in the unit cube
  for (auto& p : points) p = {unit(), unit(), unit()};
  uint64_t positive = 0;
  for (int i = 0; i < (1 << 18); ++i) {
    const uint64_t r = next();
    const auto& a = points[r & 4095];
    const auto& b = points[(r >> 12) & 4095];
    const auto& c = points[(r >> 24) & 4095];
    const auto& d = points[(r >> 36) & 4095];
    const double bx = b[0] - a[0], by = b[1] - a[1], bz = b[2] - a[2];
    const double cx = c[0] - a[0], cy = c[1] - a[1], cz = c[2] - a[2];
    const double dx = d[0] - a[0], dy = d[1] - a[1], dz = d[2] - a[2];
    const double det = bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx);
    if (det > 0.0) {
      ++positive;
    } else if (det < 0.0) {
      checksum += static_cast<uint64_t>(i);
    }
  }
  checksum ^= positive << 32;
  // 2. Sorting 2^16 random keys (integer compares, branches; cache-resident).
  std::vector<uint64_t> keys(std::size_t(1) << 16);
  for (uint64_t& k : keys) k = next();
  std::sort(keys.begin(), keys.end());
  checksum += keys[12345] ^ keys[54321];
  // 3. 2^18 gathers from the 16 MiB table (beyond the core's caches: latency and bandwidth).
  uint64_t gathered = 0;
  for (int i = 0; i < (1 << 18); ++i) gathered += table[next() & (table.size() - 1)];
  checksum += gathered;
  return {sim::ms_since(t0), checksum};
}

namespace {

// One calibration sample: the kernel on two threads at once, as a cut runs on two (its surface track and its model
// thread); wall time, ms. A machine whose second core is busy elsewhere shows it here too.
double calibration_sample() {
  const auto t0 = Clock::now();
  std::thread other;
  try {
    other = std::thread([] { calibration_kernel(); });
  } catch (const std::system_error&) {
    // No second thread to be had: the cut runs its stages on one thread then, and so does the kernel.
    calibration_kernel();
  }
  calibration_kernel();
  if (other.joinable()) other.join();
  return sim::ms_since(t0);
}

// `runs` calibration samples after one warm-up (the table, the code, the clock), appended to `ms`.
void add_calibration_samples(int runs, std::vector<double>& ms) {
  calibration_sample();
  for (int i = 0; i < runs; ++i) ms.push_back(calibration_sample());
}

}  // namespace

double calibration_ms(int runs) {
  if (runs < 1) throw std::invalid_argument("calibration needs at least one run");
  std::vector<double> ms;
  add_calibration_samples(runs, ms);
  return median_of(ms);
}

std::vector<std::string> benchmark_names() {
  std::vector<std::string> out;
  for (const Entry& e : registry()) out.push_back(e.name);
  return out;
}

std::string run_benchmarks(const std::vector<std::string>& filters, bool quiet) {
  std::vector<Entry> selected;
  for (const Entry& e : registry()) {
    const bool match = filters.empty() || std::any_of(filters.begin(), filters.end(), [&](const std::string& f) {
                         return e.name == f || e.name.rfind(f + "/", 0) == 0;
                       });
    if (match) selected.push_back(e);
  }
  for (const std::string& f : filters) {
    if (std::none_of(selected.begin(), selected.end(),
                     [&](const Entry& e) { return e.name == f || e.name.rfind(f + "/", 0) == 0; }))
      throw std::invalid_argument("no benchmark matches '" + f + "'");
  }
  // The calibration kernel runs before and after the benchmarks; its time is the median of both sets of runs, so
  // that a machine whose speed drifts during the run is measured at its average.
  std::vector<double> calibration;  // ms
  add_calibration_samples(9, calibration);
  json doc;
  doc["schema"] = "octocut.bench/1";
  doc["machine"] = {{"cpu", cpu_name()}, {"threads", int(std::thread::hardware_concurrency())}};
  doc["benchmarks"] = json::array();
  if (!quiet) std::printf("%-24s %6s %10s %10s  metrics\n", "benchmark", "runs", "median_ms", "p95_ms");
  for (const Entry& e : selected) {
    for (const BenchOutput& b : e.run()) {
      doc["benchmarks"].push_back({{"name", b.name},
                                   {"runs", b.runs},
                                   {"median_ms", b.ms.median},
                                   {"p95_ms", b.ms.p95},
                                   {"params", b.params},
                                   {"metrics", b.metrics}});
      if (!quiet) std::printf("%-24s %6ld %10.3f %10.3f  %s\n", b.name.c_str(), b.runs, b.ms.median, b.ms.p95,
                              b.metrics.dump().c_str());
    }
  }
  add_calibration_samples(9, calibration);
  doc["machine"]["calibration_ms"] = median_of(calibration);
  if (!quiet) std::printf("calibration kernel: %.3f ms (median of %zu runs)\n", median_of(calibration), calibration.size());
  return doc.dump(2) + "\n";
}

}  // namespace octocut::engine
