// The study plans: the accuracy sweep and the stability matrix as lists of `octocut run` cases.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "study_internal.hpp"

namespace octocut::engine::study {

namespace {

// A number in a case id: 1e-04, 0.002 (printf %g, which has no characters a file name cannot hold).
std::string id_num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

// `/pointer=value` with the value as compact JSON.
std::string set(const std::string& pointer, const ojson& value) { return pointer + "=" + value.dump(); }

ojson box_json(const Vec3d& lo, const Vec3d& hi) { return {{"box", {{"min", lo}, {"max", hi}}}}; }

// A study key's value, or `fallback` when the user did not set it.
ojson study_value(const std::map<std::string, ojson>& study, const std::string& key, const ojson& fallback) {
  const auto it = study.find(key);
  return it == study.end() ? fallback : it->second;
}

// Throws for a /study/ key this study does not know.
void check_study_keys(const std::map<std::string, ojson>& study, const std::vector<std::string>& known,
                      const std::string& kind) {
  for (const auto& [key, value] : study) {
    if (std::find(known.begin(), known.end(), key) == known.end()) {
      std::string list;
      for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
      throw std::invalid_argument("--set /study/" + key + ": the " + kind + " study has no such key (known: " + list +
                                  ")");
    }
  }
}

// The octree overrides of a uniform mesh at `level`.
std::vector<std::string> uniform_sets(int level) {
  return {set("/object/octree/uniform", true), set("/object/octree/base_level", level),
          set("/object/octree/max_level", level), set("/object/octree/refine", ojson::array())};
}

// The octree overrides of the scene's adaptive refinement with every level shifted by `shift`.
std::vector<std::string> adaptive_sets(const Scene& scene, int shift) {
  const OctreeSettings& o = scene.object.octree;
  ojson refine = ojson::array();
  for (const RefineRegion& r : o.refine) {
    ojson region = box_json(r.box.min, r.box.max);
    region["level"] = r.level + shift;
    refine.push_back(region);
  }
  return {set("/object/octree/uniform", false), set("/object/octree/base_level", o.base_level + shift),
          set("/object/octree/max_level", o.max_level + shift), set("/object/octree/refine", refine)};
}

// Appends `more` to `to`.
void append(std::vector<std::string>& to, const std::vector<std::string>& more) { to.insert(to.end(), more.begin(), more.end()); }

}  // namespace

std::string reproduce_command(const Plan& plan) {
  std::string c = "octocut study " + plan.kind + " " + plan.scene + " --out DIR";
  for (const std::string& s : plan.sets) c += " --set '" + s + "'";
  const ojson given = plan.settings.value("study_sets", ojson::object());
  for (const auto& [key, value] : given.items())
    c += " --set '/study/" + key + "=" + value.dump() + "'";
  return c;
}

std::map<std::string, ojson> take_study_sets(std::vector<std::string>& sets) {
  std::map<std::string, ojson> study;
  std::vector<std::string> rest;
  for (const std::string& s : sets) {
    if (s.rfind("/study/", 0) != 0) {
      rest.push_back(s);
      continue;
    }
    const auto eq = s.find('=');
    if (eq == std::string::npos) throw std::invalid_argument("--set " + s + ": expected /study/KEY=VALUE");
    const std::string key = s.substr(7, eq - 7);
    try {
      study[key] = ojson::parse(s.substr(eq + 1));
    } catch (const nlohmann::json::parse_error&) {
      throw std::invalid_argument("--set " + s + ": the value is not JSON");
    }
  }
  sets = rest;
  return study;
}

std::array<Vec3d, 2> object_bounds(const Scene& scene) {
  if (scene.object.surface_is_box) return {scene.object.surface_box.min, scene.object.surface_box.max};
  MeshLoadOptions o;
  o.scale = scene.object.scale;
  o.validate = false;
  const sim::TriMesh mesh = load_mesh(scene.object.surface_path, o).mesh;
  Vec3d lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
  for (const sim::Vec3& v : mesh.vertices) {
    for (int d = 0; d < 3; ++d) {
      lo[std::size_t(d)] = std::min(lo[std::size_t(d)], v[d]);
      hi[std::size_t(d)] = std::max(hi[std::size_t(d)], v[d]);
    }
  }
  return {lo, hi};
}

std::vector<std::string> available_elements(const std::string& scene_path) {
  try {
    load_scene(scene_path, {"/object/material/element=\"bbar\""});
    return {"trilinear", "bbar"};
  } catch (const SceneError&) {
    return {"trilinear"};
  }
}

Plan plan_accuracy(const Scene& scene, const std::map<std::string, ojson>& study) {
  if (scene.probes.empty())
    throw std::invalid_argument(scene.file + ": /probes: the accuracy study needs at least one probe (none given)");
  check_study_keys(study, {"levels", "elements", "adaptive_shifts", "tolerances", "solver_level", "dt_factors"},
                   "accuracy");
  Plan plan;
  plan.kind = "accuracy";
  const OctreeSettings& o = scene.object.octree;
  const bool dynamic = scene.solver.mode == "dynamic";
  const bool adaptive = !o.uniform && (o.max_level > o.base_level || !o.refine.empty());
  const std::vector<std::string> known = available_elements(scene.file);
  const std::vector<int> levels = study_value(study, "levels", {o.base_level, o.base_level + 1, o.base_level + 2});
  if (levels.empty()) throw std::invalid_argument("--set /study/levels: at least one level");
  const std::vector<std::string> elements = study_value(study, "elements", known);
  // The adaptive refinement shifted up by 0, 1, 2 levels, its finest static region (or its base level, when it
  // only refines where cuts go) no finer than the finest uniform level.
  int finest_static = o.base_level;
  for (const RefineRegion& r : o.refine) finest_static = std::max(finest_static, r.level);
  ojson default_shifts = ojson::array();
  for (int s = 0; s <= 2 && adaptive; ++s)
    if (finest_static + s <= *std::max_element(levels.begin(), levels.end())) default_shifts.push_back(s);
  const std::vector<int> shifts = study_value(study, "adaptive_shifts", default_shifts);
  const std::vector<double> tolerances = study_value(study, "tolerances", {1e-2, 1e-4, 1e-6, 1e-8});
  const int solver_level = study_value(study, "solver_level", levels[levels.size() / 2]);
  const std::vector<double> dt_factors = study_value(study, "dt_factors", dynamic ? ojson{4, 2, 0.5} : ojson::array());
  for (const std::string& e : elements)
    if (std::find(known.begin(), known.end(), e) == known.end())
      throw std::invalid_argument("--set /study/elements: this build has no element '" + e + "'");
  const bool element_key = known.size() > 1;  // the schema has object.material.element
  plan.settings = {{"levels", levels},         {"elements", elements},   {"adaptive_shifts", shifts},
                   {"tolerances", tolerances}, {"solver_level", solver_level}, {"dt_factors", dt_factors},
                   {"dt", scene.solver.dt},    {"mode", scene.solver.mode},   {"elements_known", known}};
  // One case: a mesh (uniform level or adaptive shift), an element, a solver and a dt factor.
  auto add = [&](const std::string& mesh, int level_or_shift, const std::string& element, const std::string& solver,
                 double tol, double dt_factor) {
    Case c;
    const bool uniform = mesh == "uniform";
    c.id = (uniform ? "uniform-L" + std::to_string(level_or_shift) : "adaptive+" + std::to_string(level_or_shift)) +
           "-" + element + "-" + solver + (solver == "pcg" ? "-" + id_num(tol) : "") +
           (dt_factor != 1.0 ? "-dt" + id_num(scene.solver.dt * dt_factor) : "");
    c.params = {{"mesh", mesh},
                {"level", uniform ? level_or_shift : o.max_level + level_or_shift},
                {"element", element},
                {"solver", solver},
                {"tolerance", solver == "pcg" ? ojson(tol) : ojson(nullptr)},
                {"dt", scene.solver.dt * dt_factor}};
    c.sets = uniform ? uniform_sets(level_or_shift) : adaptive_sets(scene, level_or_shift);
    append(c.sets, {set("/solver/linear_solver", solver), set("/output/surface_final", true),
                    set("/output/surface_every", 0), set("/render/enabled", false)});
    if (solver == "pcg") c.sets.push_back(set("/solver/tolerance", tol));
    if (dt_factor != 1.0) c.sets.push_back(set("/solver/dt", scene.solver.dt * dt_factor));
    if (element_key) c.sets.push_back(set("/object/material/element", element));
    plan.cases.push_back(std::move(c));
  };
  // The mesh sequences with the direct solver, for every element; then the solver and dt sweeps at one level.
  for (const std::string& e : elements) {
    for (int l : levels) add("uniform", l, e, "cholmod", 0.0, 1.0);
    for (int s : shifts) add("adaptive", s, e, "cholmod", 0.0, 1.0);
  }
  for (double tol : tolerances) add("uniform", solver_level, elements.front(), "pcg", tol, 1.0);
  for (double f : dt_factors) add("uniform", solver_level, elements.front(), "cholmod", 0.0, f);
  return plan;
}

namespace {

// The scenario overrides of the stability matrix for an object with bounds [lo, hi] and a run of T seconds.
std::vector<std::string> scenario_sets(const std::string& scenario, const Vec3d& lo, const Vec3d& hi, double T,
                                       double slab) {
  const double H = hi[2] - lo[2];
  const double pad = 0.1 * std::max({hi[0] - lo[0], hi[1] - lo[1], H});
  const Vec3d wide_lo{lo[0] - pad, lo[1] - pad, lo[2] - pad}, wide_hi{hi[0] + pad, hi[1] + pad, hi[2] + pad};
  // Handles: the faces at z min and z max (x min for the sag), each a slab `slab` thick inside the object.
  const ojson bottom = box_json(wide_lo, {wide_hi[0], wide_hi[1], lo[2] + slab});
  ojson top = box_json({wide_lo[0], wide_lo[1], hi[2] - slab}, wide_hi);
  ojson handles = ojson::array();
  ojson tools = ojson::array();
  if (scenario == "sag") {
    handles.push_back(box_json(wide_lo, {lo[0] + slab, wide_hi[1], wide_hi[2]}));
  } else if (scenario == "crush") {
    top["keyframes"] = ojson::array({{{"t", T / 2}, {"translation", {0.0, 0.0, -0.95 * H}}}});
    handles = {bottom, top};
  } else if (scenario == "twist") {
    top["keyframes"] = ojson::array();
    for (int k = 1; k <= 4; ++k)  // quarter turns: slerp between keyframes takes the shorter arc
      top["keyframes"].push_back({{"t", T / 2 * k / 4}, {"rotation_deg", {0.0, 0.0, 90.0 * k}}});
    handles = {bottom, top};
  } else if (scenario == "press") {
    // A kinematic rigid plate, wider than the object, from touching the top face down by half the height over the
    // first half of the run, then held; the bottom face fixed. It pushes through contact (penalty and friction).
    handles = {bottom};
    const Vec3d size{1.5 * (hi[0] - lo[0]) + 2 * pad, 1.5 * (hi[1] - lo[1]) + 2 * pad, 0.5 * H};
    const Vec3d start{0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2] + 0.25 * H};
    ojson plate = {{"name", "press"},
                   {"shape", {{"box", {{"size", size}}}}},
                   {"motion", "kinematic"},
                   {"keyframes", ojson::array({{{"t", 0.0}, {"position", start}},
                                               {{"t", T / 2}, {"position", {start[0], start[1], start[2] - 0.5 * H}}}})},
                   {"render", "none"}};
    return {set("/object/handles", handles), set("/tools", tools), set("/rigid_bodies", ojson::array({plate}))};
  } else {  // punch: 100 bites at one spot, each 0.5% of the height deeper than the last
    handles = {bottom};
    const double r = 0.15 * std::min(hi[0] - lo[0], hi[1] - lo[1]);
    const Vec3d c{0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2] + H / 2};  // blade bottom on the top face
    ojson punch = {{"name", "punch"},
                   {"blade", {{"cylinder", {{"radius", r}, {"height", H}, {"segments", 16}}}}},
                   {"keyframes", ojson::array({{{"t", 0.0}, {"position", c}},
                                               {{"t", T}, {"position", {c[0], c[1], c[2] - 0.5 * H}}}})},
                   {"cuts", ojson::array()}};
    for (int k = 1; k <= 100; ++k) punch["cuts"].push_back({{"t", T * k / 100.0 * 0.99}});
    tools.push_back(punch);
  }
  return {set("/object/handles", handles), set("/tools", tools)};
}

}  // namespace

Plan plan_stability(const Scene& scene, const std::map<std::string, ojson>& study) {
  check_study_keys(study, {"young_modulus", "poisson_ratio", "dt", "scenarios", "level", "duration"}, "stability");
  Plan plan;
  plan.kind = "stability";
  const std::vector<double> E = study_value(study, "young_modulus", {1e2, 1e4, 1e6, 1e9});
  const std::vector<double> nu = study_value(study, "poisson_ratio", {0.0, 0.3, 0.45, 0.49, 0.499});
  const std::vector<double> dt = study_value(study, "dt", {1e-4, 1e-3, 1e-2, 5e-2});
  const std::vector<std::string> scenarios =
      study_value(study, "scenarios", {"sag", "crush", "twist", "punch", "press"});
  const int level = study_value(study, "level", scene.object.octree.base_level);
  const double T = study_value(study, "duration", 0.2);
  for (const std::string& s : scenarios)
    if (s != "sag" && s != "crush" && s != "twist" && s != "punch" && s != "press")
      throw std::invalid_argument("--set /study/scenarios: no scenario '" + s + "' (sag, crush, twist, punch, press)");
  const auto [lo, hi] = object_bounds(scene);
  plan.object_size_m = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  // Handles hold the nodes on a box's faces; a mesh's handles hold a slab of a tenth of its extent.
  const double slab = scene.object.surface_is_box ? 1e-6 * plan.object_size_m : 0.1 * plan.object_size_m;
  plan.settings = {{"young_modulus", E}, {"poisson_ratio", nu}, {"dt", dt},        {"scenarios", scenarios},
                   {"level", level},     {"duration", T},       {"bounds", {lo, hi}},
                   {"skipped_scenarios", ojson::object()}, {"element", scene.object.material.element}};
  for (const std::string& s : scenarios) {
    for (double e : E) {
      for (double n : nu) {
        for (double d : dt) {
          Case c;
          c.id = s + "-E" + id_num(e) + "-nu" + id_num(n) + "-dt" + id_num(d);
          c.params = {{"scenario", s}, {"young_modulus", e}, {"poisson_ratio", n}, {"dt", d}};
          c.sets = uniform_sets(level);
          append(c.sets, {set("/object/material/young_modulus", e), set("/object/material/poisson_ratio", n),
                          set("/solver/mode", "dynamic"), set("/solver/dt", d), set("/duration", T),
                          set("/solver/threads", 1), set("/output/stability_track", true),
                          set("/output/surface_final", false), set("/output/surface_every", 0),
                          set("/render/enabled", false)});
          append(c.sets, scenario_sets(s, lo, hi, T, slab));
          plan.cases.push_back(std::move(c));
        }
      }
    }
  }
  return plan;
}

namespace {
// A shell word in single quotes.
std::string quote(const std::string& s) {
  std::string q = "'";
  for (char ch : s) q += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  return q + "'";
}
}  // namespace

std::vector<std::string> case_argv(const Plan& plan, const Case& c, const fs::path& out_dir) {
  std::vector<std::string> argv = {plan.executable, "run", plan.scene};
  for (const std::string& s : plan.sets) argv.insert(argv.end(), {"--set", s});
  for (const std::string& s : c.sets) argv.insert(argv.end(), {"--set", s});
  argv.insert(argv.end(), {"--out", (fs::absolute(out_dir) / "cases" / c.id).string(), "--no-render", "--quiet"});
  return argv;
}

std::string case_command(const Plan& plan, const Case& c, const fs::path& out_dir) {
  std::string line;
  for (const std::string& a : case_argv(plan, c, out_dir)) line += (line.empty() ? "" : " ") + quote(a);
  return line;
}

ojson plan_json(const Plan& plan, const fs::path& out_dir) {
  ojson j;
  j["schema"] = "octocut.study_plan/1";
  j["kind"] = plan.kind;
  j["scene"] = plan.scene;
  j["executable"] = plan.executable;
  j["sets"] = plan.sets;
  j["reference"] = plan.reference;
  j["settings"] = plan.settings;
  j["object_size_m"] = plan.object_size_m;
  j["cases"] = ojson::array();
  for (const Case& c : plan.cases)
    j["cases"].push_back({{"id", c.id}, {"params", c.params}, {"sets", c.sets}, {"command", case_command(plan, c, out_dir)}});
  return j;
}

Plan plan_from_json(const ojson& j, const std::string& file) {
  try {
    if (j.at("schema") != "octocut.study_plan/1") throw std::invalid_argument(file + ": /schema: not octocut.study_plan/1");
    Plan p;
    p.kind = j.at("kind");
    p.scene = j.at("scene");
    p.executable = j.at("executable");
    p.sets = j.at("sets").get<std::vector<std::string>>();
    p.reference = j.at("reference");
    p.settings = j.at("settings");
    p.object_size_m = j.at("object_size_m");
    for (const ojson& c : j.at("cases")) p.cases.push_back({c.at("id"), c.at("params"), c.at("sets")});
    return p;
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(file + ": not a study plan: " + e.what());
  }
}

}  // namespace octocut::engine::study
