// The accuracy study's references besides Richardson: a file of probe values from another code, and CalculiX.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>

#include "octocut/engine/io/io.hpp"
#include "octocut/engine/run/scene_object.hpp"
#include "study_internal.hpp"

namespace octocut::engine::study {

ojson read_reference_file(const std::string& path, const Scene& scene) {
  ojson j;
  try {
    j = ojson::parse(read_file(path));
  } catch (const std::runtime_error& e) {
    throw std::invalid_argument("--reference " + path + ": " + e.what());
  }
  std::string names;
  for (const Probe& p : scene.probes) names += (names.empty() ? "" : ", ") + p.name;
  if (!j.is_object() || !j.contains("probes") || !j["probes"].is_object())
    throw std::invalid_argument(path + ": expected {\"probes\": {\"NAME\": [ux, uy, uz]}}");
  for (const auto& [key, v] : j.items())
    if (key != "probes") throw std::invalid_argument(path + ": /" + key + ": unknown key (only /probes)");
  if (j["probes"].empty()) throw std::invalid_argument(path + ": /probes: no probe given");
  ojson out = ojson::object();
  for (const auto& item : j["probes"].items()) {
    const std::string name = item.key();  // a plain variable: lambdas cannot capture structured bindings in clang 14
    const auto& v = item.value();
    const bool known = std::any_of(scene.probes.begin(), scene.probes.end(), [&](const Probe& p) { return p.name == name; });
    if (!known)
      throw std::invalid_argument(path + ": /probes/" + name + ": the scene " + scene.file + " has no probe '" + name +
                                  "' (its probes: " + (names.empty() ? "none" : names) + ")");
    if (!v.is_array() || v.size() != 3 || !v[0].is_number() || !v[1].is_number() || !v[2].is_number())
      throw std::invalid_argument(path + ": /probes/" + name + ": expected [ux, uy, uz], m");
    out[name] = v;
  }
  return out;
}

namespace {

// CalculiX's C3D8 corner order from ours (corner k at bits x, y, z): bottom face counter-clockwise, then the top.
constexpr int kC3d8Order[8] = {0, 1, 3, 2, 4, 5, 7, 6};

// The deck: nodes and C3D8 elements of the uniform model, the handles' nodes clamped, gravity on the density, one
// linear static step, the displacements printed to the .dat file. `node_of_slot` receives the node of each slot.
std::string ccx_deck(const Scene& scene, const sim::ObjectModel& model, std::vector<int>& node_of_slot) {
  const double h = model.edge().front();
  const sim::Vec3 lo = to_vec3(scene.object.surface_box.min);
  std::map<std::array<long, 3>, int> nodes;  // grid index -> node number (1-based)
  std::ostringstream n, e, fix;
  n.precision(17);
  node_of_slot.assign(model.slot_rest().size(), 0);
  for (std::size_t s = 0; s < model.slot_rest().size(); ++s) {
    const sim::Vec3 x = model.slot_rest()[s];
    const std::array<long, 3> key = {std::lround((x[0] - lo[0]) / h), std::lround((x[1] - lo[1]) / h),
                                     std::lround((x[2] - lo[2]) / h)};
    auto [it, added] = nodes.emplace(key, int(nodes.size()) + 1);
    node_of_slot[s] = it->second;
    if (!added) continue;
    n << it->second << ", " << x[0] << ", " << x[1] << ", " << x[2] << "\n";
    const bool clamped = std::any_of(scene.object.handles.begin(), scene.object.handles.end(), [&](const Handle& hd) {
      for (int d = 0; d < 3; ++d)
        if (x[d] < hd.box.min[std::size_t(d)] || x[d] > hd.box.max[std::size_t(d)]) return false;
      return true;
    });
    if (clamped) fix << it->second << ", 1, 3\n";
  }
  for (int el = 0; el < model.num_elements(); ++el) {
    e << el + 1;
    for (int k : kC3d8Order) e << ", " << node_of_slot[8 * std::size_t(el) + std::size_t(k)];
    e << "\n";
  }
  const Material& m = scene.object.material;
  const std::array<double, 3>& g = scene.solver.gravity;
  const double gn = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  std::ostringstream d;
  d.precision(17);
  d << "** octocut study: " << scene.file << " as C3D8 on its uniform octree mesh (h = " << h << " m)\n"
    << "*NODE, NSET=NALL\n" << n.str() << "*ELEMENT, TYPE=C3D8, ELSET=EALL\n" << e.str()
    << "*MATERIAL, NAME=TISSUE\n*ELASTIC\n" << m.young_modulus << ", " << m.poisson_ratio << "\n*DENSITY\n"
    << m.density << "\n*SOLID SECTION, ELSET=EALL, MATERIAL=TISSUE\n*BOUNDARY\n" << fix.str() << "*STEP\n*STATIC\n";
  if (gn > 0.0) d << "*DLOAD\nEALL, GRAV, " << gn << ", " << g[0] / gn << ", " << g[1] / gn << ", " << g[2] / gn << "\n";
  d << "*NODE PRINT, NSET=NALL\nU\n*END STEP\n";
  return d.str();
}

// The displacements in a ccx .dat file: node -> [ux, uy, uz], m.
std::map<int, Vec3d> read_ccx_displacements(const fs::path& dat) {
  std::ifstream in(dat);
  std::map<int, Vec3d> u;
  std::string line;
  bool in_block = false;
  while (std::getline(in, line)) {
    if (line.find("displacements (vx,vy,vz)") != std::string::npos) {
      in_block = true;
      continue;
    }
    if (!in_block) continue;
    std::istringstream s(line);
    int node = 0;
    Vec3d v{};
    if (s >> node >> v[0] >> v[1] >> v[2]) u[node] = v;
  }
  return u;
}

}  // namespace

ojson ccx_reference(const Scene& scene_in, int level, const fs::path& work_dir) {
  // What ccx can check here: a static box with clamped handles and no tools.
  const std::string why = "--reference ccx supports static box scenes with fixed handles and no cuts: ";
  if (!scene_in.object.surface_is_box) throw std::invalid_argument(why + scene_in.file + " has a mesh surface");
  if (scene_in.solver.mode != "static") throw std::invalid_argument(why + scene_in.file + " is dynamic");
  for (const Handle& hd : scene_in.object.handles)
    if (!hd.keyframes.empty()) throw std::invalid_argument(why + scene_in.file + " has a moving handle");
  for (const ToolSettings& t : scene_in.tools)
    if (!t.cuts.empty()) throw std::invalid_argument(why + scene_in.file + " has cut events");
  if (std::system("command -v ccx >/dev/null 2>&1") != 0)
    throw std::runtime_error("--reference ccx: the CalculiX solver `ccx` is not installed (Debian package "
                             "calculix-ccx); install it, or pass --reference FILE or no reference (Richardson)");
  // The same uniform mesh the study runs at `level`: every leaf must be full (the box on the octree's grid).
  Scene scene = scene_in;
  scene.object.octree.uniform = true;
  scene.object.octree.base_level = scene.object.octree.max_level = level;
  scene.object.octree.refine.clear();
  const SceneObject object = build_scene_object(scene);
  const sim::ObjectModel& model = object.model;
  for (double occ : model.occupancy())
    if (occ < 1.0 - 1e-9) throw std::invalid_argument(why + "the box is not aligned with the octree's level-" +
                                                      std::to_string(level) + " grid (a leaf is partly full)");
  std::vector<int> node_of_slot;
  fs::create_directories(work_dir);
  write_file_atomic(work_dir / "deck.inp", ccx_deck(scene, model, node_of_slot));
  const std::string cmd = "cd '" + work_dir.string() + "' && ccx -i deck > ccx.log 2>&1";
  if (std::system(cmd.c_str()) != 0 || !fs::exists(work_dir / "deck.dat"))
    throw std::runtime_error("--reference ccx: ccx failed on " + (work_dir / "deck.inp").string() + " (see ccx.log)");
  const std::map<int, Vec3d> u = read_ccx_displacements(work_dir / "deck.dat");
  // Each probe: ccx's nodal displacements interpolated trilinearly in the element that holds it.
  std::vector<sim::Vec3> slots(node_of_slot.size());
  for (std::size_t s = 0; s < slots.size(); ++s) {
    const auto it = u.find(node_of_slot[s]);
    if (it == u.end()) throw std::runtime_error("--reference ccx: deck.dat lacks node " + std::to_string(node_of_slot[s]));
    slots[s] = sim::Vec3(it->second[0], it->second[1], it->second[2]);
  }
  ojson probes = ojson::object();
  for (const Probe& p : scene.probes) {
    const auto e = model.embed(to_vec3(p.point));
    if (!e) throw std::invalid_argument("/probes: probe " + p.name + " lies outside the object");
    const sim::Vec3 v = model.evaluate(*e, slots);
    probes[p.name] = {v[0], v[1], v[2]};
  }
  return probes;
}

}  // namespace octocut::engine::study
