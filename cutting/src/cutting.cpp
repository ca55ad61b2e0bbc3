#include "octocut/cutting/cutting.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <future>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <system_error>
#include <thread>

#include "octocut/cutting/blade.hpp"
#include "octocut/cutting/shape_matching.hpp"
#include "octocut/cutting/surface_cut.hpp"
#include "octocut/sim/dof_map.hpp"
#include "octocut/sim/disjoint_sets.hpp"

namespace octocut::cutting {

bool pipeline_available() { return true; }

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

using UnionFind = sim::DisjointSets;  // union-find; the root of a set is its smallest member

bool boxes_overlap(const sim::Box3& a, const sim::Box3& b) {
  return (a.min.array() <= b.max.array()).all() && (b.min.array() <= a.max.array()).all();
}

sim::Box3 grow(const sim::Box3& a, const sim::Box3& b) { return {a.min.cwiseMin(b.min), a.max.cwiseMax(b.max)}; }

// Groups `leaves` (leaf indices of `model`) by material connectivity among themselves: two leaves are united when
// they share a face through which material connects. Index i of the result is leaves[i].
UnionFind material_groups(const sim::ObjectModel& model, const std::vector<int>& leaves) {
  const sim::RootGeometry& root = model.root();
  std::vector<sim::Box3> box(leaves.size());  // rest boxes, m
  for (std::size_t i = 0; i < leaves.size(); ++i) box[i] = root.cell_box(model.tree().leaf(leaves[i]));
  UnionFind uf(leaves.size());
  // Candidate pairs by a sweep along x: boxes sorted by their lower x, each compared with those that start before
  // it ends (the union-find's result does not depend on the order of the unions).
  std::vector<std::size_t> order(leaves.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return box[a].min.x() != box[b].min.x() ? box[a].min.x() < box[b].min.x() : a < b;
  });
  for (std::size_t oi = 0; oi < order.size(); ++oi) {
    const std::size_t i = order[oi];
    for (std::size_t oj = oi + 1; oj < order.size() && box[order[oj]].min.x() <= box[i].max.x(); ++oj) {
      const std::size_t j = order[oj];
      if (!boxes_overlap(box[i], box[j])) continue;  // no common face
      const auto face = sim::common_face(model.tree().leaf(leaves[i]), model.tree().leaf(leaves[j]), root);
      if (face && model.material().face_connected(face->first, face->second)) uf.unite(int(i), int(j));
    }
  }
  return uf;
}

// Connected components of a triangle mesh's triangles (through shared vertices): component of each triangle (|F|).
std::vector<int> triangle_components(const sim::TriMesh& mesh, int& count) {
  UnionFind uf(mesh.vertices.size());
  for (const auto& t : mesh.triangles) {
    uf.unite(t[0], t[1]);
    uf.unite(t[0], t[2]);
  }
  std::vector<int> id(mesh.vertices.size(), -1), comp(mesh.triangles.size());
  count = 0;
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const int r = uf.find(mesh.triangles[f][0]);
    if (id[std::size_t(r)] < 0) id[std::size_t(r)] = count++;
    comp[f] = id[std::size_t(r)];
  }
  return comp;
}

// SPEC §4 stage 2: B'_i cuts only the material of component i. Returns one flag per leaf of `model` (empty when
// no leaf is flagged): the leaves of other components whose rest boxes meet the rest-space blade, flagged when,
// within a neighbourhood of the blade, their material does not connect to the component's (leaves connect when
// their rows of P share a DOF: node splitting gives the material on either side of a cut its own DOFs). Such
// material lies under B'_i in rest space only: in the deformed state the blade never touched it (a part folded or
// pushed away from where the component's transform puts the blade). The neighbourhood is the blade's box grown by
// two of the largest leaf edges in play, so that a leaf at the blade's fringe whose material reaches the component
// just outside the box (around the rim of a thin part, say) counts as the component's own. When no leaf of the
// component lies in the neighbourhood, nothing is flagged and the cut is not restricted.
std::vector<char> foreign_leaves(const sim::ObjectModel& model, const BladeVolume& blade,
                                 const std::vector<int>& component) {
  const auto own = [&](int e) { return std::binary_search(component.begin(), component.end(), e); };
  // Only leaves of other components can be foreign: the component's own leaves need no exact blade test.
  std::vector<int> candidates;  // leaves under the blade (rest space) that are not the component's, ascending
  for (int e = 0; e < model.num_elements(); ++e) {
    if (own(e)) continue;
    const sim::Box3 b = model.root().cell_box(model.tree().leaf(e));
    if (boxes_overlap(b, blade.bounds()) && blade.overlaps_box(b)) candidates.push_back(e);
  }
  if (candidates.empty() || component.empty()) return {};
  double h = 0.0;  // largest edge among the candidates and the component's leaves, m
  for (const int e : candidates) h = std::max(h, model.edge()[std::size_t(e)]);
  for (const int e : component) h = std::max(h, model.edge()[std::size_t(e)]);
  // The neighbourhood: the candidates first, then every other leaf whose box meets the grown box.
  const sim::Box3 near{blade.bounds().min.array() - 2.0 * h, blade.bounds().max.array() + 2.0 * h};
  std::vector<int> context = candidates;
  for (int e = 0; e < model.num_elements(); ++e) {
    if (boxes_overlap(model.root().cell_box(model.tree().leaf(e)), near) &&
        !std::binary_search(candidates.begin(), candidates.end(), e)) {
      context.push_back(e);
    }
  }
  UnionFind uf = sim::element_groups(model, context);
  std::vector<char> legit(context.size(), 0);  // per root
  bool any_own = false;
  for (std::size_t i = 0; i < context.size(); ++i) {
    if (!own(context[i])) continue;
    legit[std::size_t(uf.find(int(i)))] = 1;
    any_own = true;
  }
  if (!any_own) return {};
  std::vector<char> foreign(std::size_t(model.num_elements()), 0);
  bool any = false;
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    if (legit[std::size_t(uf.find(int(i)))]) continue;
    foreign[std::size_t(candidates[i])] = 1;
    any = true;
  }
  if (!any) return {};
  return foreign;
}

// Whether the rest point p lies in a leaf that `foreign` (from foreign_leaves) flags.
bool in_foreign(const sim::ObjectModel& model, const std::vector<char>& foreign, const sim::Vec3& p) {
  if (foreign.empty()) return false;
  const auto at = model.embed(p);
  return at && foreign[std::size_t(at->leaf)];
}

// A failure of one stage: the cut is skipped with this reason.
struct StageFailure : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// What stages 3 and 4 and the solver preparation produce (see run_model_stages).
struct ModelWork {
  std::string error;                                ///< why a stage failed; empty when none did
  bool dead_empty = true;                           ///< the blades touch no tet of M
  int tets_removed = 0, leaves_refined = 0, fragments_removed = 0;
  double fragment_volume = 0.0;                     ///< m^3
  std::shared_ptr<const sim::MaterialGraph> graph;  ///< M after the cut
  bool all_gone = false;                            ///< no material is left
  std::vector<int> fragment_leaves;                 ///< leaves of *before_fragments that the fragments held
  std::optional<sim::ObjectModel> before_fragments; ///< the split model, kept only when fragments go
  std::shared_ptr<const sim::ObjectModel> next;     ///< the new revision; null when no material is left
  double ms_material_graph = 0.0, ms_refine = 0.0, ms_node_split = 0.0;
  // The second phase, after model_ready: only read once the model thread has been joined.
  std::string prepare_error;                        ///< why prepare_model failed; empty when it did not
  sim::PreparedModel prepared;                      ///< *next's copy, its state and its symbolic analysis
  bool have_prepared = false;                       ///< `prepared` holds the revision
  double ms_prepare = 0.0;
};

// Stages 3 (material graph) and 4 (refine, node split, fragments), then the new revision's FEM system, carried-over
// state and symbolic analysis (the solver part of stage 5), for the rest-space blades. Reads the simulator and M,
// changes nothing. Calls model_ready() once everything but the preparation is in `w` (from then on the caller may
// read those fields while the preparation runs), and skips the preparation when cancelled() says so. Throws
// StageFailure.
void run_model_stages(ModelWork& w, const std::vector<sim::TriMesh>& blades,
                      const std::vector<std::vector<char>>& foreign,
                      const std::shared_ptr<const sim::MaterialGraph>& material_ptr,
                      const sim::ObjectModel& model, const sim::Simulator& simulator, const CutOptions& options,
                      double inscribed_radius, const std::function<void()>& model_ready,
                      const std::function<bool()>& cancelled) {
  const sim::RootGeometry& root = model.root();
  const sim::MaterialGraph& material = *material_ptr;
  // ---- 3. material_graph -------------------------------------------------------------------------------------------
  auto t0 = Clock::now();
  std::vector<int> dead;
  std::vector<sim::Box3> changed;
  std::vector<BladeVolume> rest_volumes;
  for (std::size_t k = 0; k < blades.size(); ++k) {
    rest_volumes.emplace_back(blades[k]);
    std::vector<int> tets = tets_touched(material, rest_volumes.back());
    // Only the tets of the blade's own component (by the leaf that holds their centroid).
    std::erase_if(tets, [&](int t) {
      const std::array<sim::Vec3, 4> p = material.tet(t);
      return in_foreign(model, foreign[k], 0.25 * (p[0] + p[1] + p[2] + p[3]));
    });
    if (tets.empty()) continue;
    sim::Box3 region{sim::Vec3::Constant(INFINITY), sim::Vec3::Constant(-INFINITY)};
    for (int t : tets) {
      for (const sim::Vec3& p : material.tet(t)) region = grow(region, {p, p});
    }
    changed.push_back(region);
    dead.insert(dead.end(), tets.begin(), tets.end());
  }
  std::sort(dead.begin(), dead.end());
  dead.erase(std::unique(dead.begin(), dead.end()), dead.end());
  w.tets_removed = int(dead.size());
  w.dead_empty = dead.empty();
  std::shared_ptr<const sim::MaterialGraph> graph =
      dead.empty() ? material_ptr : material.without(dead);
  w.ms_material_graph = ms_since(t0);

  // ---- 4. refine, then node_split ----------------------------------------------------------------------------------
  t0 = Clock::now();
  const double le = inscribed_radius / std::sqrt(3.0);
  // Leaves that meet a rest-space blade with an edge above l_e, level after level, refined in one revision. When
  // tets go, that revision takes the new material too: the leaves the cut touches are measured once and the DOFs
  // are split in the same update, so with_material below finds its work done.
  auto meets_blade = [&](const sim::Cell& c) {
    if (c.level >= model.max_level() || !(root.cell_edge(c) > le)) return false;
    const sim::Box3 box = root.cell_box(c);
    for (std::size_t k = 0; k < rest_volumes.size(); ++k) {
      const BladeVolume& bv = rest_volumes[k];
      if (boxes_overlap(box, bv.bounds()) && bv.overlaps_box(box) &&
          !in_foreign(model, foreign[k], 0.5 * (box.min + box.max)))
        return true;
    }
    return false;
  };
  sim::ObjectModel next = !dead.empty() && graph->num_tets() > 0
                              ? model.refined_with_material(meets_blade, graph, changed, &w.leaves_refined)
                              : model.refined_where(meets_blade, &w.leaves_refined);
  w.ms_refine = ms_since(t0);

  t0 = Clock::now();
  if (!dead.empty()) {
    if (graph->num_tets() == 0) {
      w.all_gone = true;
    } else {
      next = next.with_material(graph, changed);
      w.all_gone = next.num_elements() == 0;
    }
  }
  // Loose pieces: components of elements that no handle holds. Without any handle, the largest piece counts as
  // the body and only the others are loose.
  if (!w.all_gone && options.fragments != FragmentPolicy::none) {
    int count = 0;
    const std::vector<int> comp = sim::element_components(next, count);
    if (count > 1) {
      const std::vector<sim::ComponentInfo> info = sim::component_info(next, comp, count);
      const bool any_anchor = std::any_of(info.begin(), info.end(), [](const auto& c) { return c.anchored; });
      int body = -1;
      if (!any_anchor) {
        body = 0;
        for (int c = 1; c < count; ++c)
          if (info[std::size_t(c)].volume > info[std::size_t(body)].volume) body = c;
      }
      std::vector<char> remove(std::size_t(count), 0);
      for (int c = 0; c < count; ++c) {
        const auto& ci = info[std::size_t(c)];
        if (ci.anchored || c == body) continue;
        if (options.fragments == FragmentPolicy::small && !(ci.volume < options.fragment_volume)) continue;
        remove[std::size_t(c)] = 1;
        ++w.fragments_removed;
        w.fragment_volume += ci.volume;
      }
      for (int e = 0; e < next.num_elements(); ++e)
        if (remove[std::size_t(comp[std::size_t(e)])]) w.fragment_leaves.push_back(e);
    }
  }
  if (!w.fragment_leaves.empty()) {
    if (w.fragment_leaves.size() == std::size_t(next.num_elements())) {
      w.all_gone = true;
      w.before_fragments = std::move(next);
    } else {
      sim::ObjectModel rest = next.without_leaves(w.fragment_leaves);
      w.before_fragments = std::move(next);
      next = std::move(rest);
    }
  }
  w.graph = std::move(graph);
  if (!w.all_gone) w.next = std::make_shared<const sim::ObjectModel>(std::move(next));
  w.ms_node_split = ms_since(t0);
  model_ready();

  // ---- 5. (the solver part) -----------------------------------------------------------------------------------------
  if (w.all_gone || cancelled()) return;
  t0 = Clock::now();
  w.prepared = simulator.prepare_model(*w.next, true);  // a copy: the caller reads *w.next meanwhile
  w.have_prepared = true;
  w.ms_prepare = ms_since(t0);
}

}  // namespace

void index_surface(CutObject& object) {
  // Room for the cuts to append to S without moving it (apply_cut keeps room when it compacts S).
  const auto room = [](std::size_t n) { return n + n / 8 + 1024; };
  object.surface.vertices.reserve(room(object.surface.vertices.size()));
  object.surface.triangles.reserve(room(object.surface.triangles.size()));
  object.cut_faces.reserve(room(object.surface.triangles.size()));
  auto grid = std::make_unique<FaceGrid>();
  grid->build(object.surface);
  object.grid.grid = std::move(grid);
  object.grid.vertices = object.surface.vertices.size();
  object.grid.triangles = object.surface.triangles.size();
}

bool surface_indexed(const CutObject& object) {
  return object.grid.grid != nullptr && object.grid.vertices == object.surface.vertices.size() &&
         object.grid.triangles == object.surface.triangles.size();
}

CutOutcome apply_cut(CutObject& object, sim::Simulator& simulator, sim::SurfaceEmbedding& embedding,
                     const CutRequest& request, const CutOptions& options) {
  CutOutcome out;
  const auto t_total = Clock::now();
  auto finish = [&](std::string status, std::string reason) {
    out.status = std::move(status);
    out.reason = std::move(reason);
    out.ms.total = ms_since(t_total);
    return out;
  };
  if (object.removed) return finish("no-op", "the object has been cut away entirely");
  if (!object.graph) return finish("skipped", "the object has no material graph");
  if (!(request.inscribed_radius > 0.0) || !std::isfinite(request.inscribed_radius))
    return finish("skipped", "the blade has no positive inscribed radius");

  try {
    const sim::ObjectModel& model = simulator.model();
    const sim::RootGeometry& root = model.root();

    // ---- 1. back_transform -------------------------------------------------------------------------------------
    auto t0 = Clock::now();
    const BladeVolume blade(request.blade);
    const sim::Box3 blade_box = blade.bounds();
    std::vector<sim::Vec3> slots;
    model.dofs().prolong(simulator.state().x, slots);
    std::vector<int> touched;
    for (int e = 0; e < model.num_elements(); ++e) {
      std::array<sim::Vec3, 8> c;
      sim::Box3 hb{sim::Vec3::Constant(INFINITY), sim::Vec3::Constant(-INFINITY)};
      bool finite = true;
      for (int k = 0; k < 8; ++k) {
        c[std::size_t(k)] = slots[8 * std::size_t(e) + std::size_t(k)];
        finite = finite && c[std::size_t(k)].allFinite();
        hb.min = hb.min.cwiseMin(c[std::size_t(k)]);
        hb.max = hb.max.cwiseMax(c[std::size_t(k)]);
      }
      if (!finite) throw StageFailure("back_transform: the deformed state is not finite");
      if (boxes_overlap(hb, blade_box) && blade.overlaps_hexahedron(c)) touched.push_back(e);
    }
    if (touched.empty()) {
      out.ms.back_transform = ms_since(t0);
      return finish("no-op", "the blade meets no element");
    }
    // Components: touched leaves that share a face through which material connects.
    UnionFind uf = material_groups(model, touched);
    std::vector<std::vector<int>> groups;
    {
      std::vector<int> gid(touched.size(), -1);
      for (std::size_t i = 0; i < touched.size(); ++i) {
        const int r = uf.find(int(i));
        if (gid[std::size_t(r)] < 0) {
          gid[std::size_t(r)] = int(groups.size());
          groups.emplace_back();
        }
        groups[std::size_t(gid[std::size_t(r)])].push_back(touched[i]);
      }
    }
    out.components = int(groups.size());
    std::vector<sim::TriMesh> rest_blades;
    std::vector<std::vector<char>> foreign;  // per rest blade: the leaves it must not cut (see foreign_leaves)
    for (const std::vector<int>& g : groups) {
      std::vector<sim::Vec3> rest, deformed;
      std::vector<double> weights;
      for (int e : g) {
        const double h = model.edge()[std::size_t(e)];
        const double w = model.occupancy()[std::size_t(e)] * h * h * h / 8.0;
        for (int k = 0; k < 8; ++k) {
          rest.push_back(model.slot_rest()[8 * std::size_t(e) + std::size_t(k)]);
          deformed.push_back(slots[8 * std::size_t(e) + std::size_t(k)]);
          weights.push_back(w);
        }
      }
      ShapeMatch match;
      try {
        match = shape_match(rest, deformed, weights, options.max_condition);
      } catch (const std::invalid_argument& e) {
        throw StageFailure(std::string("back_transform: shape matching failed: ") + e.what());
      }
      out.max_blend = std::max(out.max_blend, match.blend);
      sim::TriMesh rest_blade = to_rest(match, request.blade);
      // A back-transform that moves no vertex by more than rounding (an object at rest) is the identity: the
      // blade is used as given, so that repeated cuts at rest meet earlier cut faces exactly, not 1e-19 m off.
      double moved = 0.0;
      for (std::size_t v = 0; v < rest_blade.vertices.size(); ++v)
        moved = std::max(moved, (rest_blade.vertices[v] - request.blade.vertices[v]).cwiseAbs().maxCoeff());
      if (moved <= 1e-12 * root.size) rest_blade = request.blade;
      foreign.push_back(foreign_leaves(model, BladeVolume(rest_blade), g));
      if (!foreign.back().empty()) ++out.restricted_components;
      rest_blades.push_back(std::move(rest_blade));
    }
    out.ms.back_transform = ms_since(t0);

    // Stages 3 and 4 and the new revision's solver preparation read only M, T, the state and the rest-space blades,
    // never S: they run on a second thread (the model thread) while this one cuts S (stage 2). Once the new revision
    // is known, that thread prepares its FEM system and symbolic analysis while this one updates the embedding.
    // Nothing is committed before both are done, and the results do not depend on the interleaving.
    const auto model_stages = [&](ModelWork& w, const std::vector<sim::TriMesh>& blades, std::promise<void>* ready,
                                  const std::function<bool()>& cancelled) {
      bool signalled = false;
      const auto signal = [&] {
        if (signalled) return;
        signalled = true;
        if (ready) ready->set_value();
      };
      try {
        run_model_stages(w, blades, foreign, object.graph, model, simulator, options, request.inscribed_radius, signal,
                         cancelled);
      } catch (const std::exception& e) {
        std::string why =
            dynamic_cast<const StageFailure*>(&e) ? e.what() : std::string("unexpected error: ") + e.what();
        (signalled ? w.prepare_error : w.error) = std::move(why);
      }
      signal();
    };
    ModelWork work;
    std::promise<void> model_ready;
    std::future<void> model_known = model_ready.get_future();
    // Its destructor asks it to skip the preparation and joins it, on every way out of this function. Without a
    // thread to be had, the model stages run here first.
    std::jthread model_thread;
    try {
      model_thread = std::jthread([&, blades = rest_blades](std::stop_token stop) {
        model_stages(work, blades, &model_ready, [stop] { return stop.stop_requested(); });
      });
    } catch (const std::system_error&) {
      model_stages(work, rest_blades, &model_ready, [] { return false; });
    }

    // ---- 2. surface ------------------------------------------------------------------------------------------------
    t0 = Clock::now();
    // S is edited in place (its grid finds the faces near each blade); the journal undoes every edit when a later
    // stage fails. Vertices that no triangle uses any more stay in S until stage 5 compacts it.
    if (!surface_indexed(object)) {  // O(|S|): only when the caller did not index S
      try {
        index_surface(object);
      } catch (const std::invalid_argument& e) {
        throw StageFailure(std::string("surface: ") + e.what());
      }
    }
    SurfaceEditor editor(object.surface, *object.grid.grid, &object.cut_faces);
    struct Rollback {  // on every way out without a commit
      SurfaceEditor& editor;
      bool armed = true;
      ~Rollback() {
        if (armed) editor.rollback(0);
      }
    } rollback{editor};
    const std::size_t vertices_before = object.surface.vertices.size();  // S.vertices[0, vertices_before) are old
    std::vector<int32_t> unused;  // vertices of S that no triangle uses any more, ascending
    bool surface_changed = false;
    SurfaceCutOptions sopt;
    sopt.verify = options.verify;
    sopt.check_blade_self_intersection = false;  // blades are checked when loaded (or built convex)
    // S checked once, and changed since only by verified cuts (which check every changed face against its
    // neighbours), stays free of self-intersections: CGAL need not check it again.
    sopt.check_surface_self_intersection = !object.surface_checked;
    std::vector<char> unrestricted(rest_blades.size(), 0);  // per blade: its restriction was dropped
    for (std::size_t k = 0; k < rest_blades.size(); ++k) {
      sim::TriMesh& b = rest_blades[k];
      if (object.surface.triangles.empty()) break;
      sopt.removable = nullptr;
      if (!foreign[k].empty())
        sopt.removable = [&model, &f = foreign[k]](const sim::Vec3& p) { return !in_foreign(model, f, p); };
      // A degenerate configuration that the boolean refuses is retried with the blade moved by 1e-9, then 1e-7,
      // of its size; the blade that was used is the one the model stages must use too. A failed attempt leaves S
      // as it was.
      auto [r, moves] = cut_surface_in_place_perturbing(editor, b, sopt);
      // The restriction decides per region of S and of the blade, by one point each, and leaves are coarser than
      // S: where a region straddles the border of the foreign material, the kept pieces need not close up and the
      // boolean refuses its result. B'_i then cuts without the restriction (as if nothing were foreign), and the
      // model stages run again without it too.
      if (r.status == SurfaceCutStatus::failed && sopt.removable) {
        sopt.removable = nullptr;
        sim::TriMesh unrestricted_blade = b;
        auto [again, again_moves] = cut_surface_in_place_perturbing(editor, unrestricted_blade, sopt);
        if (again.status != SurfaceCutStatus::failed) {
          b = std::move(unrestricted_blade);
          r = std::move(again);
          moves = again_moves;
          unrestricted[k] = 1;
          ++out.unrestricted;
          --out.restricted_components;
        }
      }
      if (moves > 0) ++out.perturbed;
      if (r.status == SurfaceCutStatus::failed) throw StageFailure("surface: " + r.reason);
      if (r.status == SurfaceCutStatus::no_op) continue;
      out.removed_volume += r.removed_volume;
      std::vector<int32_t> merged;
      merged.reserve(unused.size() + r.removed_vertices.size());
      std::merge(unused.begin(), unused.end(), r.removed_vertices.begin(), r.removed_vertices.end(),
                 std::back_inserter(merged));
      unused = std::move(merged);
      surface_changed = true;
    }
    out.ms.surface = ms_since(t0);

    model_known.wait();
    // A perturbed blade removes material where it now is, and one whose restriction was dropped removes all the
    // material under it: the model stages run again, here, with the blades and restrictions used.
    if (out.perturbed > 0 || out.unrestricted > 0) {
      model_thread.request_stop();
      if (model_thread.joinable()) model_thread.join();
      for (std::size_t k = 0; k < unrestricted.size(); ++k) {
        if (unrestricted[k]) foreign[k].clear();
      }
      work = ModelWork{};
      model_stages(work, rest_blades, nullptr, [] { return false; });
    }
    if (!work.error.empty()) throw StageFailure(work.error);
    out.tets_removed = work.tets_removed;
    out.leaves_refined = work.leaves_refined;
    out.fragments_removed = work.fragments_removed;
    out.fragment_volume = work.fragment_volume;
    out.ms.material_graph = work.ms_material_graph;
    out.ms.refine = work.ms_refine;
    out.ms.node_split = work.ms_node_split;
    if (work.dead_empty && !surface_changed) return finish("no-op", "the blade removes no material");

    // The surface parts that lie in the removed pieces go with them: a component of S whose vertices mostly lie in
    // removed leaves.
    bool all_gone = work.all_gone;
    if (!work.fragment_leaves.empty()) {
      t0 = Clock::now();
      const sim::ObjectModel& split = *work.before_fragments;  // the model whose leaves fragment_leaves lists
      std::vector<char> gone_leaf(std::size_t(split.num_elements()), 0);
      for (int e : work.fragment_leaves) gone_leaf[std::size_t(e)] = 1;
      int ncomp = 0;
      const sim::TriMesh& current = object.surface;
      const std::vector<int> tcomp = triangle_components(current, ncomp);
      std::vector<int> in_gone(std::size_t(ncomp), 0), total(std::size_t(ncomp), 0);
      std::vector<char> seen(current.vertices.size(), 0);
      for (std::size_t f = 0; f < current.triangles.size(); ++f) {
        for (int32_t v : current.triangles[f]) {
          if (seen[std::size_t(v)]) continue;
          seen[std::size_t(v)] = 1;
          ++total[std::size_t(tcomp[f])];
          const auto pe = split.embed(current.vertices[std::size_t(v)]);
          if (pe && gone_leaf[std::size_t(pe->leaf)]) ++in_gone[std::size_t(tcomp[f])];
        }
      }
      std::vector<int32_t> drop;  // triangles of the removed components, ascending
      for (std::size_t f = 0; f < current.triangles.size(); ++f) {
        const int c = tcomp[f];
        if (2 * in_gone[std::size_t(c)] > total[std::size_t(c)]) drop.push_back(int32_t(f));
      }
      if (!drop.empty()) {
        editor.remove_faces(drop);
        // The vertices that no triangle uses any more join `unused`.
        std::vector<char> used(current.vertices.size(), 0);
        for (const auto& t : current.triangles)
          for (int32_t v : t) used[std::size_t(v)] = 1;
        unused.clear();
        for (std::size_t v = 0; v < used.size(); ++v)
          if (!used[v]) unused.push_back(int32_t(v));
        surface_changed = true;
      }
      out.ms.node_split += ms_since(t0);
    }

    // ---- 5. embedding, then the solver -----------------------------------------------------------------------------
    t0 = Clock::now();
    if (all_gone) {
      // Nothing is left to simulate: the object is gone. The simulator keeps its last model but is no longer run.
      editor.commit();
      rollback.armed = false;
      object.surface = sim::TriMesh{};
      object.grid = SurfaceGrid{};
      object.cut_faces.clear();
      object.graph = work.graph;
      object.removed = true;
      out.ms.embedding = ms_since(t0);
      return finish("ok", "");
    }
    // S compacted: the vertices no triangle uses go, the others keep their order (the embedding's edit: old ones
    // removed, new ones appended). The edit gets its own triangles; S itself is compacted in place at the commit.
    sim::SurfaceEdit edit;
    const auto n = int32_t(object.surface.vertices.size());
    std::vector<int32_t> old_to_new(static_cast<std::size_t>(n));  // (|V|): the new index of each vertex, -1 for an unused one
    {
      const sim::TriMesh& current = object.surface;
      int32_t from = 0, shift = 0;
      for (const int32_t v : unused) {
        std::iota(old_to_new.begin() + from, old_to_new.begin() + v, from - shift);
        old_to_new[std::size_t(v)] = -1;
        if (std::size_t(v) < vertices_before) edit.removed_vertices.push_back(int(v));
        from = v + 1;
        ++shift;
      }
      std::iota(old_to_new.begin() + from, old_to_new.end(), from - shift);
      for (std::size_t v = vertices_before; v < current.vertices.size(); ++v)
        if (old_to_new[v] >= 0) edit.inserted_rest.push_back(current.vertices[v]);
      edit.triangles = current.triangles;
      if (!unused.empty()) {
        const int32_t first_unused = unused.front();  // below it, indices stay
        for (auto& t : edit.triangles)
          for (int32_t& v : t)
            if (v > first_unused) v = old_to_new[std::size_t(v)];
      }
    }
    embedding.update(*work.next, std::move(edit));  // strong guarantee: unchanged when it throws
    out.ms.embedding = ms_since(t0);

    if (model_thread.joinable()) model_thread.join();
    t0 = Clock::now();
    if (work.have_prepared) {
      simulator.adopt(std::move(work.prepared));
      out.ms.solver_update = work.ms_prepare + ms_since(t0);
    } else {
      // The preparation failed on the model thread (it only allocates and analyses, so it should not): as
      // set_model and refresh_solver, whose failed analysis the next step handles.
      simulator.set_model(*work.next);
      try {
        simulator.refresh_solver();
      } catch (const std::exception&) {
      }
      out.ms.solver_update = ms_since(t0);
    }

    // Commit the object. The grid's triangles keep their indices and their vertices their positions.
    editor.commit();
    rollback.armed = false;
    if (!unused.empty()) {
      // In place: the used vertices move down over the unused ones (no allocation; room stays for the next cut).
      std::vector<sim::Vec3>& vs = object.surface.vertices;
      for (int32_t v = unused.front() + 1; v < n; ++v)
        if (old_to_new[std::size_t(v)] >= 0) vs[std::size_t(old_to_new[std::size_t(v)])] = vs[std::size_t(v)];
      vs.resize(vs.size() - unused.size());
      // The embedding holds the remapped triangles (the edit's, taken over): copied into S's own storage.
      object.surface.triangles.assign(embedding.triangles().begin(), embedding.triangles().end());
    }
    object.grid.vertices = object.surface.vertices.size();
    object.grid.triangles = object.surface.triangles.size();
    object.graph = std::move(work.graph);
    object.surface_checked = object.surface_checked && options.verify;
    return finish("ok", "");
  } catch (const StageFailure& e) {
    return finish("skipped", e.what());
  } catch (const std::exception& e) {
    return finish("skipped", std::string("unexpected error: ") + e.what());
  }
}

}  // namespace octocut::cutting
