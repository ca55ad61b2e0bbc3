#include "octocut/cutting/cutting.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <deque>
#include <functional>
#include <future>
#include <iterator>
#include <numeric>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>

#include "octocut/cutting/blade.hpp"
#include "octocut/cutting/shape_matching.hpp"
#include "octocut/cutting/surface_cut.hpp"
#include "octocut/sim/dof_map.hpp"
#include "octocut/sim/disjoint_sets.hpp"
#include "octocut/sim/timing.hpp"

namespace octocut::cutting {

namespace {

using sim::Clock;
using sim::ms_since;

using UnionFind = sim::DisjointSets;  // union-find; the root of a set is its smallest member

bool boxes_overlap(const sim::Box3& a, const sim::Box3& b) {
  return (a.min.array() <= b.max.array()).all() && (b.min.array() <= a.max.array()).all();
}

sim::Box3 grow(const sim::Box3& a, const sim::Box3& b) { return {a.min.cwiseMin(b.min), a.max.cwiseMax(b.max)}; }

// Calls visit(i, j) for every pair of the closed boxes `box` that meet, found by a sweep along x: boxes sorted by
// their lower x, each compared with those that start before it ends (in the sweep's order, not by index).
template <class Visit>
void for_each_meeting_pair(const std::vector<sim::Box3>& box, Visit&& visit) {
  std::vector<std::size_t> order(box.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return box[a].min.x() != box[b].min.x() ? box[a].min.x() < box[b].min.x() : a < b;
  });
  for (std::size_t oi = 0; oi < order.size(); ++oi) {
    const std::size_t i = order[oi];
    for (std::size_t oj = oi + 1; oj < order.size() && box[order[oj]].min.x() <= box[i].max.x(); ++oj) {
      const std::size_t j = order[oj];
      if (boxes_overlap(box[i], box[j])) visit(i, j);
    }
  }
}

// The rest boxes of `leaves` (leaf indices of `model`), m.
std::vector<sim::Box3> leaf_boxes(const sim::ObjectModel& model, const std::vector<int>& leaves) {
  std::vector<sim::Box3> box(leaves.size());
  for (std::size_t i = 0; i < leaves.size(); ++i) box[i] = model.root().cell_box(model.tree().leaf(leaves[i]));
  return box;
}

// Whether two meshes are the same, bit for bit (a blade and the same blade mapped the same way).
bool same_mesh(const sim::TriMesh& a, const sim::TriMesh& b) {
  return a.vertices == b.vertices && a.triangles == b.triangles;
}

// Groups `leaves` (leaf indices of `model`) by material connectivity among themselves: two leaves are united when
// they share a face through which material connects. Index i of the result is leaves[i]. (The union-find's result
// does not depend on the order of the unions.)
UnionFind material_groups(const sim::ObjectModel& model, const std::vector<int>& leaves) {
  UnionFind uf(leaves.size());
  for_each_meeting_pair(leaf_boxes(model, leaves), [&](std::size_t i, std::size_t j) {
    const auto face = sim::common_face(model.tree().leaf(leaves[i]), model.tree().leaf(leaves[j]), model.root());
    if (face && model.material().face_connected(face->first, face->second)) uf.unite(int(i), int(j));
  });
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
//
// One ForeignLeaves serves the components of one cut. What depends only on the rest-space blade (the leaves under
// it) and on the neighbourhood (its leaves' material groups) is kept per distinct blade and edge h: after a re-cut
// beside an earlier hole the touched elements fall into dozens of components whose blades snap onto one, and each
// component then needs only its own leaves' groups. The flags are those of computing everything per component (the
// groups are a partition of the same leaves whatever the order).
class ForeignLeaves {
 public:
  explicit ForeignLeaves(const sim::ObjectModel& model) : m_model(model) {}

  // The flags for the rest-space blade `blade` of the component `component` (its leaves, ascending).
  std::vector<char> operator()(const sim::TriMesh& blade, const std::vector<int>& component) {
    const std::size_t u = under_blade(blade);
    const Under& under = m_under[u];
    const auto own = [&](int e) { return std::binary_search(component.begin(), component.end(), e); };
    std::vector<int> candidates;  // leaves under the blade (rest space) that are not the component's, ascending
    for (const int e : under.leaves)
      if (!own(e)) candidates.push_back(e);
    if (candidates.empty() || component.empty()) return {};
    double h = 0.0;  // largest edge among the candidates and the component's leaves, m
    for (const int e : candidates) h = std::max(h, m_model.edge()[std::size_t(e)]);
    for (const int e : component) h = std::max(h, m_model.edge()[std::size_t(e)]);
    const std::vector<int>& group = groups_near(u, h);
    std::vector<char> legit(group.size(), 0);  // per group (its smallest leaf)
    bool any_own = false;
    for (const int e : component) {
      const int g = group[std::size_t(e)];
      if (g < 0) continue;
      legit[std::size_t(g)] = 1;
      any_own = true;
    }
    if (!any_own) return {};
    std::vector<char> foreign(std::size_t(m_model.num_elements()), 0);
    bool any = false;
    for (const int e : candidates) {
      if (legit[std::size_t(group[std::size_t(e)])]) continue;
      foreign[std::size_t(e)] = 1;
      any = true;
    }
    if (!any) return {};
    return foreign;
  }

 private:
  struct Under {
    sim::TriMesh blade;       ///< rest space, m
    sim::Box3 bounds;         ///< BladeVolume's bounds of it, m
    std::vector<int> leaves;  ///< leaves whose rest boxes meet the blade, ascending
  };
  struct Near {
    std::size_t under = 0;   ///< index into m_under
    double h = 0.0;          ///< the edge the neighbourhood was grown by, m
    std::vector<int> group;  ///< per leaf: the smallest leaf of its material group in the neighbourhood, or -1
  };

  // The index in m_under of `blade`'s entry, made when it is new.
  std::size_t under_blade(const sim::TriMesh& blade) {
    for (std::size_t k = 0; k < m_under.size(); ++k)
      if (same_mesh(m_under[k].blade, blade)) return k;
    const BladeVolume volume(blade);
    Under u{blade, volume.bounds(), {}};
    for (int e = 0; e < m_model.num_elements(); ++e) {
      const sim::Box3 b = m_model.root().cell_box(m_model.tree().leaf(e));
      if (boxes_overlap(b, u.bounds) && volume.overlaps_box(b)) u.leaves.push_back(e);
    }
    m_under.push_back(std::move(u));
    return m_under.size() - 1;
  }

  // The neighbourhood: every leaf whose box meets the blade's box grown by 2 h (the leaves under the blade among
  // them), grouped by material connectivity.
  const std::vector<int>& groups_near(std::size_t index, double h) {
    for (const Near& n : m_near)
      if (n.under == index && n.h == h) return n.group;
    const Under& under = m_under[index];
    const sim::Box3 near{under.bounds.min.array() - 2.0 * h, under.bounds.max.array() + 2.0 * h};
    std::vector<int> context;  // ascending
    for (int e = 0; e < m_model.num_elements(); ++e)
      if (boxes_overlap(m_model.root().cell_box(m_model.tree().leaf(e)), near)) context.push_back(e);
    UnionFind uf = sim::element_groups(m_model, context);
    Near n{index, h, std::vector<int>(std::size_t(m_model.num_elements()), -1)};
    for (std::size_t i = 0; i < context.size(); ++i)
      n.group[std::size_t(context[i])] = context[std::size_t(uf.find(int(i)))];
    m_near.push_back(std::move(n));
    return m_near.back().group;
  }

  const sim::ObjectModel& m_model;
  std::deque<Under> m_under;  // a deque: the references handed out stay valid
  std::deque<Near> m_near;
};

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

// ---- 1. back_transform ---------------------------------------------------------------------------------------------

// The rest-space blades of stage 1 (B'_i, one per touched material component) and what each must not cut.
struct RestBlades {
  std::vector<sim::TriMesh> blades;        ///< closed, outward-oriented, rest space, m
  std::vector<std::vector<char>> foreign;  ///< per blade: the leaves it must not cut (see foreign_leaves)
};

// The elements whose deformed hexahedra (`slots`: 8 deformed corners per element, m) meet the blade, ascending.
// Throws StageFailure when the deformed state is not finite.
std::vector<int> touched_elements(const sim::ObjectModel& model, const std::vector<sim::Vec3>& slots,
                                  const BladeVolume& blade) {
  const sim::Box3 blade_box = blade.bounds();
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
  return touched;
}

// The leaves that are not touched but whose boxes touch a touched leaf's (a ring one leaf deep), ascending.
std::vector<int> touched_ring(const sim::ObjectModel& model, const std::vector<int>& touched) {
  const sim::RootGeometry& root = model.root();
  sim::Box3 all{sim::Vec3::Constant(INFINITY), sim::Vec3::Constant(-INFINITY)};  // m
  for (int e : touched) all = grow(all, root.cell_box(model.tree().leaf(e)));
  // Candidates: the leaves whose boxes meet the touched leaves' box; then, by a sweep along x over the candidates and
  // the touched leaves together, those that meet a touched leaf's box.
  std::vector<int> list;  // candidates first (not touched), then the touched leaves
  for (int e = 0; e < model.num_elements(); ++e)
    if (!std::binary_search(touched.begin(), touched.end(), e) &&
        boxes_overlap(root.cell_box(model.tree().leaf(e)), all))
      list.push_back(e);
  const std::size_t candidates = list.size();
  list.insert(list.end(), touched.begin(), touched.end());
  std::vector<char> in_ring(candidates, 0);
  for_each_meeting_pair(leaf_boxes(model, list), [&](std::size_t i, std::size_t j) {
    if ((i < candidates) != (j < candidates)) in_ring[std::min(i, j)] = 1;
  });
  std::vector<int> ring;
  for (std::size_t i = 0; i < candidates; ++i)
    if (in_ring[i]) ring.push_back(list[i]);
  return ring;
}

// The touched elements grouped into components: touched leaves connected by material through the faces they share
// or through the leaves around them, up to kRingDepth leaves deep, that the blade does not touch. Along the wall an
// earlier cut left, the leaves that a re-cut touches hold pieces of the material beside it, which often meet only
// through the leaves behind them: without the ring a re-cut at one pose fell into dozens of components (78 on a
// sagging sphere re-cut by a box blade, 997 over slab_punch_100's 100 punches), each with its own rest-space map
// and blade. Material that is folded or pushed together but does not connect within that ring stays apart.
// Components come in the order of their first element, each ascending.
constexpr int kRingDepth = 2;  // leaves of the ring around the touched ones, counted outwards

std::vector<std::vector<int>> touched_components(const sim::ObjectModel& model, const std::vector<int>& touched) {
  // Connected among themselves already (most cuts): the ring cannot change that.
  UnionFind alone = material_groups(model, touched);
  bool one = true;
  for (std::size_t i = 0; i < touched.size() && one; ++i) one = alone.find(int(i)) == 0;
  if (one) return touched.empty() ? std::vector<std::vector<int>>{} : std::vector<std::vector<int>>{touched};
  std::vector<int> context = touched;  // the touched leaves first, then the rings
  std::vector<int> inner = touched;    // ascending
  for (int depth = 0; depth < kRingDepth; ++depth) {
    const std::vector<int> ring = touched_ring(model, inner);
    context.insert(context.end(), ring.begin(), ring.end());
    std::vector<int> grown;
    std::merge(inner.begin(), inner.end(), ring.begin(), ring.end(), std::back_inserter(grown));
    inner = std::move(grown);
  }
  UnionFind uf = material_groups(model, context);
  std::vector<std::vector<int>> groups;
  std::vector<int> gid(context.size(), -1);
  for (std::size_t i = 0; i < touched.size(); ++i) {
    const int r = uf.find(int(i));
    if (gid[std::size_t(r)] < 0) {
      gid[std::size_t(r)] = int(groups.size());
      groups.emplace_back();
    }
    groups[std::size_t(gid[std::size_t(r)])].push_back(touched[i]);
  }
  return groups;
}

// The blade of one component in rest space: the request's blade mapped back by the component's shape-matching
// affine map (its slots' rest and deformed positions, weighted by material volume). Raises out.max_blend. Throws
// StageFailure when shape matching fails.
sim::TriMesh rest_blade(const sim::ObjectModel& model, const std::vector<sim::Vec3>& slots,
                        const std::vector<int>& component, const CutRequest& request, const CutOptions& options,
                        CutOutcome& out) {
  std::vector<sim::Vec3> rest, deformed;
  std::vector<double> weights;
  for (int e : component) {
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
  sim::TriMesh blade = to_rest(match, request.blade);
  // A back-transform that moves no vertex by more than rounding (an object at rest) is the identity: the blade is
  // used as given, so that repeated cuts at rest meet earlier cut faces exactly, not 1e-19 m off.
  double moved = 0.0;
  for (std::size_t v = 0; v < blade.vertices.size(); ++v)
    moved = std::max(moved, (blade.vertices[v] - request.blade.vertices[v]).cwiseAbs().maxCoeff());
  if (moved <= 1e-12 * model.root().size) blade = request.blade;
  return blade;
}

// Near-coincident walls snap together: a rest-space blade within options.min_feature of a recent cut's blade or of
// another component's blade of this cut (`earlier`), where S's material can be (`region`: S's bounds grown by
// min_feature), becomes that blade exactly (snap_target), so that its walls coincide with the walls that blade left
// or leaves instead of landing micrometres beside them. Returns the index in `earlier` of the blade it snaps to, or
// -1. Only the first `count` of `earlier` are candidates.
int snap_index(const std::vector<sim::TriMesh>& earlier, std::size_t count, const sim::Box3& region,
               const CutOptions& options, const sim::TriMesh& blade) {
  if (!(options.min_feature > 0.0) || count == 0) return -1;
  if (count == earlier.size()) return snap_target(blade, earlier, region, options.min_feature);
  return snap_target(blade, std::vector<sim::TriMesh>(earlier.begin(), earlier.begin() + std::ptrdiff_t(count)),
                     region, options.min_feature);
}

// The blade of component g (rest space, m) after snapping, and what it must not cut. An unrestricted blade (no
// foreign leaves) snaps to the latest of `earlier` within min_feature; a restricted one only to the first `recent`
// of them, the recent cuts' blades (the same blade restricted to two components would meet, exactly, the walls it
// has just made in the other). Whether the blade as mapped is restricted (a pass over the leaves under it) is asked
// only where it decides: when the latest one within min_feature is one of this cut's, or when it snaps to none.
// Either way the result is that of asking first.
std::vector<char> snapped_blade(ForeignLeaves& foreign_leaves, const std::vector<sim::TriMesh>& earlier,
                                std::size_t recent, const sim::Box3& region, const CutOptions& options,
                                const std::vector<int>& g, sim::TriMesh& b, CutOutcome& out) {
  std::optional<std::vector<char>> mapped_foreign;  // of b as mapped, once asked
  int k = snap_index(earlier, earlier.size(), region, options, b);
  if (k >= int(recent)) {
    mapped_foreign = foreign_leaves(b, g);
    if (!mapped_foreign->empty()) k = snap_index(earlier, recent, region, options, b);
  }
  if (k >= 0) {
    b = earlier[std::size_t(k)];
    ++out.snapped;
    return foreign_leaves(b, g);
  }
  return mapped_foreign ? std::move(*mapped_foreign) : foreign_leaves(b, g);
}

// S's rest-space bounds, m: those the grid keeps when it matches S (computed here the first time), else a pass over S.
sim::Box3 surface_bounds(const CutObject& object) {
  if (!surface_indexed(object)) return sim::bounds(object.surface);
  if (!object.grid.bounds) object.grid.bounds = sim::bounds(object.surface);
  return *object.grid.bounds;
}

// Stage 1: the leaves whose deformed hexahedra meet the blade, grouped into face- and material-connected
// components; per component a shape-matching affine map takes the blade into rest space (B'_i), restricted to the
// component's material (foreign_leaves). No blade when the blade meets no element. Throws StageFailure.
RestBlades back_transform(const CutObject& object, const sim::ObjectModel& model, const sim::SimState& state,
                          const CutRequest& request, const CutOptions& options, CutOutcome& out) {
  const BladeVolume blade(request.blade);
  std::vector<sim::Vec3> slots;
  model.dofs().prolong(state.x, slots);
  const std::vector<int> touched = touched_elements(model, slots, blade);
  if (touched.empty()) return {};
  const std::vector<std::vector<int>> groups = touched_components(model, touched);
  out.components = int(groups.size());
  RestBlades rest;
  std::vector<sim::TriMesh> earlier = object.recent_blades;  // what a blade may snap to
  sim::Box3 region{sim::Vec3::Zero(), sim::Vec3::Zero()};      // m
  // S's bounds only when a blade may snap: after earlier cuts, or with several components (the grid keeps them).
  if (options.min_feature > 0.0 && !object.surface.triangles.empty() && (!earlier.empty() || groups.size() > 1)) {
    region = surface_bounds(object);
    region.min -= sim::Vec3::Constant(options.min_feature);
    region.max += sim::Vec3::Constant(options.min_feature);
  }
  const std::size_t recent = earlier.size();
  ForeignLeaves foreign_leaves(model);
  for (const std::vector<int>& g : groups) {
    sim::TriMesh b = rest_blade(model, slots, g, request, options, out);
    std::vector<char> foreign;
    if (object.surface.triangles.empty()) {
      foreign = foreign_leaves(b, g);
    } else {
      const int before = out.snapped;
      foreign = snapped_blade(foreign_leaves, earlier, recent, region, options, g, b, out);
      if (out.snapped == before && foreign.empty()) earlier.push_back(b);  // one that snapped is among them already
    }
    if (!foreign.empty()) ++out.restricted_components;
    rest.foreign.push_back(std::move(foreign));
    rest.blades.push_back(std::move(b));
  }
  return rest;
}

// ---- 3. material_graph, 4. refine and node_split (the model stages) --------------------------------------------------

// What stages 3 and 4 and the solver preparation produce (see run_model_stages).
struct ModelWork {
  std::string error;                                ///< why a stage failed; empty when none did
  bool dead_empty = true;                           ///< the blades touch no tet of M
  int tets_removed = 0, leaves_refined = 0, fragments_removed = 0;
  double fragment_volume = 0.0;                     ///< m^3
  bool all_gone = false;                            ///< no material is left
  std::vector<int> fragment_leaves;                 ///< leaves of *before_fragments that the fragments held
  std::optional<sim::ObjectModel> before_fragments; ///< the split model, kept only when fragments go
  std::shared_ptr<const sim::ObjectModel> next;     ///< the new revision, which holds M after the cut; null when no
                                                    ///< material is left
  double ms_material_graph = 0.0, ms_refine = 0.0, ms_node_split = 0.0;
  // The second phase, after model_ready: only read once the model thread has been joined.
  std::string prepare_error;                        ///< why prepare_model failed; empty when it did not
  sim::PreparedModel prepared;                      ///< *next's copy, its state and its symbolic analysis
  bool have_prepared = false;                       ///< `prepared` holds the revision
  double ms_prepare = 0.0;
};

// Stage 3's result: the tets of M that the blades remove, and M without them.
struct DeadTets {
  std::vector<int> tets;                            ///< ascending, each once
  std::vector<sim::Box3> changed;                   ///< rest-space boxes that cover them, m (one per blade)
  std::shared_ptr<const sim::MaterialGraph> graph;  ///< M without them; null when none dies
};

// Stage 3: the tets of M (`material`) that meet a rest-space blade, each blade's own component's only (by the leaf
// that holds the tet's centroid), removed from M.
DeadTets material_graph_stage(const sim::ObjectModel& model, const sim::MaterialGraph& material,
                              const std::vector<BladeVolume>& rest_volumes,
                              const std::vector<std::vector<char>>& foreign) {
  DeadTets dead;
  for (std::size_t k = 0; k < rest_volumes.size(); ++k) {
    std::vector<int> tets = tets_touched(material, rest_volumes[k]);
    std::erase_if(tets, [&](int t) {
      const std::array<sim::Vec3, 4> p = material.tet(t);
      return in_foreign(model, foreign[k], 0.25 * (p[0] + p[1] + p[2] + p[3]));
    });
    if (tets.empty()) continue;
    sim::Box3 region{sim::Vec3::Constant(INFINITY), sim::Vec3::Constant(-INFINITY)};
    for (int t : tets) {
      for (const sim::Vec3& p : material.tet(t)) region = grow(region, {p, p});
    }
    dead.changed.push_back(region);
    dead.tets.insert(dead.tets.end(), tets.begin(), tets.end());
  }
  std::sort(dead.tets.begin(), dead.tets.end());
  dead.tets.erase(std::unique(dead.tets.begin(), dead.tets.end()), dead.tets.end());
  if (!dead.tets.empty()) dead.graph = material.without(dead.tets);
  return dead;
}

// Stage 4, refine: the leaves that meet a rest-space blade (outside its foreign material) with an edge above
// l_e = r / sqrt(3), level after level, refined in one revision. When tets die, that revision takes the new
// material too: the leaves the cut touches are measured once and the DOFs split in the same update.
sim::ObjectModel refine_stage(const sim::ObjectModel& model, const std::vector<BladeVolume>& rest_volumes,
                              const std::vector<std::vector<char>>& foreign, const DeadTets& dead,
                              double inscribed_radius, int& leaves_refined) {
  const sim::RootGeometry& root = model.root();
  const double le = inscribed_radius / std::sqrt(3.0);
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
  return dead.graph && dead.graph->num_tets() > 0
             ? model.refined_with_material(meets_blade, dead.graph, dead.changed, &leaves_refined)
             : model.refined_where(meets_blade, &leaves_refined);
}

// The loose pieces of `next` to remove per options.fragments: components of elements that no handle holds (without
// any handle, the largest piece counts as the body and only the others are loose). Counts them into w and returns
// their leaves, ascending.
std::vector<int> loose_fragments(const sim::ObjectModel& next, const CutOptions& options, ModelWork& w) {
  int count = 0;
  const std::vector<int> comp = sim::element_components(next, count);
  if (count <= 1) return {};
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
  std::vector<int> leaves;
  for (int e = 0; e < next.num_elements(); ++e)
    if (remove[std::size_t(comp[std::size_t(e)])]) leaves.push_back(e);
  return leaves;
}

// Stage 4, node_split: the refined revision takes M without the dead tets (DOFs split where the material no longer
// connects), then the loose fragments go per options. Fills w.all_gone, the fragment fields and w.next.
void node_split_stage(sim::ObjectModel next, const DeadTets& dead, const CutOptions& options, ModelWork& w) {
  if (!dead.tets.empty()) {
    if (dead.graph->num_tets() == 0) {
      w.all_gone = true;
    } else {
      next = next.with_material(dead.graph, dead.changed);
      w.all_gone = next.num_elements() == 0;
    }
  }
  if (!w.all_gone && options.fragments != FragmentPolicy::none) w.fragment_leaves = loose_fragments(next, options, w);
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
  if (!w.all_gone) w.next = std::make_shared<const sim::ObjectModel>(std::move(next));
}

// The blades that stages 3 and 4 need (indices, ascending): a blade that repeats another one exactly removes and
// refines nothing more when that other is unrestricted (no foreign leaves: it removes and refines everything under
// it) or restricted alike and earlier in the list. A re-cut beside an earlier hole can fall into dozens of components
// whose blades all snap onto one; the stages then test each tet and leaf against it once.
std::vector<std::size_t> distinct_blades(const std::vector<sim::TriMesh>& blades,
                                         const std::vector<std::vector<char>>& foreign) {
  std::vector<std::size_t> keep;
  for (std::size_t k = 0; k < blades.size(); ++k) {
    bool covered = false;
    for (std::size_t j = 0; j < blades.size() && !covered; ++j) {
      if (j == k || !same_mesh(blades[j], blades[k])) continue;
      covered = foreign[j].empty() ? (j < k || !foreign[k].empty()) : (j < k && foreign[j] == foreign[k]);
    }
    if (!covered) keep.push_back(k);
  }
  return keep;
}

// Stages 3 (material graph) and 4 (refine, node split, fragments), then the new revision's FEM system, carried-over
// state and symbolic analysis (the solver part of stage 5), for the rest-space blades. Reads the simulator and M
// (through its model), changes nothing. Calls model_ready() once everything but the preparation is in `w` (from
// then on the caller may read those fields while the preparation runs), and skips the preparation when cancelled()
// says so; spare_time() says whether the preparation may also do work of the first step after the cut (see
// Simulator::prepare_model). Throws StageFailure.
void run_model_stages(ModelWork& w, const std::vector<sim::TriMesh>& blades,
                      const std::vector<std::vector<char>>& foreign, const sim::Simulator& simulator,
                      const CutOptions& options, double inscribed_radius, const std::function<void()>& model_ready,
                      const std::function<bool()>& cancelled, const std::function<bool()>& spare_time) {
  const sim::ObjectModel& model = simulator.model();
  auto t0 = Clock::now();
  std::vector<BladeVolume> rest_volumes;
  std::vector<std::vector<char>> distinct_foreign;
  for (const std::size_t k : distinct_blades(blades, foreign)) {
    rest_volumes.emplace_back(blades[k]);
    distinct_foreign.push_back(foreign[k]);
  }
  const DeadTets dead = material_graph_stage(model, *model.material_graph(), rest_volumes, distinct_foreign);
  w.tets_removed = int(dead.tets.size());
  w.dead_empty = dead.tets.empty();
  w.ms_material_graph = ms_since(t0);

  t0 = Clock::now();
  sim::ObjectModel next =
      refine_stage(model, rest_volumes, distinct_foreign, dead, inscribed_radius, w.leaves_refined);
  w.ms_refine = ms_since(t0);

  t0 = Clock::now();
  node_split_stage(std::move(next), dead, options, w);
  w.ms_node_split = ms_since(t0);
  model_ready();

  // The solver part of stage 5.
  if (w.all_gone || cancelled()) return;
  t0 = Clock::now();
  w.prepared = simulator.prepare_model(*w.next, true, spare_time);  // a copy: the caller reads *w.next meanwhile
  w.have_prepared = true;
  w.ms_prepare = ms_since(t0);
}

// The model stages on a second thread (the model thread) while this one cuts S (stage 2): they read only M, T, the
// state and the rest-space blades, never S. Once the new revision is known, that thread prepares its FEM system and
// symbolic analysis while this one updates the embedding. Nothing is committed before both are done, and the
// results do not depend on the interleaving. Without a thread to be had, the stages run here at once. On every way
// out, the destructor asks the thread to skip the preparation and joins it.
class ModelStages {
 public:
  ModelStages(const sim::Simulator& simulator, const CutOptions& options, double inscribed_radius,
              const RestBlades& rest)
      : m_simulator(simulator), m_options(options), m_radius(inscribed_radius), m_known(m_ready.get_future()) {
    // The thread holds `this`: a ModelStages never moves.
    try {
      m_thread = std::jthread([this, blades = rest.blades, foreign = rest.foreign](std::stop_token stop) {
        run(blades, foreign, &m_ready, [stop] { return stop.stop_requested(); });
      });
    } catch (const std::system_error&) {
      run(rest.blades, rest.foreign, &m_ready, [] { return false; });
    }
  }

  ModelStages(const ModelStages&) = delete;
  ModelStages& operator=(const ModelStages&) = delete;
  ~ModelStages() = default;

  // Stages 3 and 4 as the model thread ran them, once they are done (the preparation may still run).
  ModelWork& model_known() {
    m_known.wait();
    return m_work;
  }

  // Stages 3 and 4 run again, here, with the blades and restrictions the surface stage used; the first run is
  // stopped and joined.
  ModelWork& rerun(const RestBlades& rest) {
    m_thread.request_stop();
    if (m_thread.joinable()) m_thread.join();
    m_work = ModelWork{};
    run(rest.blades, rest.foreign, nullptr, [] { return false; });
    return m_work;
  }

  // The surface stage has ended (spare_time above).
  void surface_done() { m_surface_done.store(true, std::memory_order_release); }

  // Everything, the preparation included: the thread is joined.
  ModelWork& finished() {
    if (m_thread.joinable()) m_thread.join();
    return m_work;
  }

 private:
  // run_model_stages into m_work, its error kept as the reason of the stage it stopped (or of the preparation).
  void run(const std::vector<sim::TriMesh>& blades, const std::vector<std::vector<char>>& foreign,
           std::promise<void>* ready, const std::function<bool()>& cancelled) {
    bool signalled = false;
    const auto signal = [&] {
      if (signalled) return;
      signalled = true;
      if (ready) ready->set_value();
    };
    try {
      // The first step's share of the preparation is done here while the surface stage still runs on the other
      // core (on the 50k meniscus it ends 1-3 ms after this thread's stages), not when this thread would keep the
      // cut waiting. The choice changes no result.
      const auto spare_time = [this] { return !m_surface_done.load(std::memory_order_acquire); };
      run_model_stages(m_work, blades, foreign, m_simulator, m_options, m_radius, signal, cancelled, spare_time);
    } catch (const std::exception& e) {
      std::string why = dynamic_cast<const StageFailure*>(&e) ? e.what() : std::string("unexpected error: ") + e.what();
      (signalled ? m_work.prepare_error : m_work.error) = std::move(why);
    }
    signal();
  }

  const sim::Simulator& m_simulator;
  const CutOptions& m_options;
  double m_radius;             ///< the blade's inscribed radius, m
  ModelWork m_work;
  std::promise<void> m_ready;  ///< set once stages 3 and 4 are in m_work
  std::future<void> m_known;
  std::atomic<bool> m_surface_done{false};
  std::jthread m_thread;       ///< declared last: stopped and joined before the members it uses go
};

// Stages 3 and 4 for the blades as stage 2 used them: a perturbed blade removes material where it now is, and one
// whose restriction was dropped removes all the material under it, so then they run again, here. Their figures go
// into `out`; throws StageFailure with their error.
ModelWork& model_stages_done(ModelStages& stages, RestBlades& rest, const std::vector<char>& unrestricted,
                             CutOutcome& out) {
  ModelWork* work = &stages.model_known();
  if (out.perturbed > 0 || out.unrestricted > 0) {
    for (std::size_t k = 0; k < unrestricted.size(); ++k) {
      if (unrestricted[k]) rest.foreign[k].clear();
    }
    work = &stages.rerun(rest);
  }
  if (!work->error.empty()) throw StageFailure(work->error);
  out.tets_removed = work->tets_removed;
  out.leaves_refined = work->leaves_refined;
  out.fragments_removed = work->fragments_removed;
  out.fragment_volume = work->fragment_volume;
  out.ms.material_graph = work->ms_material_graph;
  out.ms.refine = work->ms_refine;
  out.ms.node_split = work->ms_node_split;
  return *work;
}

// ---- 2. surface ----------------------------------------------------------------------------------------------------

// The edits of one cut to S, as a transaction. The editor edits S in place (its grid finds the faces near each
// blade) and journals every edit; vertices that no triangle uses any more stay in S until compact() removes them.
// Unless commit() is called, the destructor undoes the compaction and then rolls the journal back: S, its grid and
// CutObject::cut_faces are as they were.
class SurfaceTransaction {
 public:
  // Throws StageFailure when S has to be indexed (the caller did not) and is invalid.
  explicit SurfaceTransaction(CutObject& object)
      : m_object(indexed(object)), m_editor(m_object.surface, *m_object.grid.grid, &m_object.cut_faces),
        m_vertices_before(m_object.surface.vertices.size()) {}
  SurfaceTransaction(const SurfaceTransaction&) = delete;
  SurfaceTransaction& operator=(const SurfaceTransaction&) = delete;
  ~SurfaceTransaction() {
    if (m_committed) return;
    if (m_compacted) uncompact();
    m_editor.rollback(0);
  }

  [[nodiscard]] SurfaceEditor& editor() { return m_editor; }

  // Removes from S the vertices `unused` (ascending) that no triangle uses: the others move down in order (no
  // allocation; room stays for the next cuts) and the triangles are renumbered in place. Returns the embedding's
  // edit: the removed vertices that S had before this cut, and the number of vertices this cut added that stay.
  sim::SurfaceEdit compact(std::span<const int32_t> unused, sim::Executor& exec) {
    std::vector<sim::Vec3>& vs = m_object.surface.vertices;
    sim::SurfaceEdit edit;
    m_unused.assign(unused.begin(), unused.end());
    m_unused_positions.clear();
    for (const int32_t v : unused) {
      m_unused_positions.push_back(vs[std::size_t(v)]);
      if (std::size_t(v) < m_vertices_before) edit.removed_vertices.push_back(int(v));
    }
    edit.inserted = int(vs.size() - m_vertices_before) - int(unused.size() - edit.removed_vertices.size());
    if (unused.empty()) return edit;
    // The new index of each vertex after the first unused one, -1 for an unused one.
    const auto n = int32_t(vs.size());
    const int32_t first = unused.front();
    std::vector<int32_t> old_to_new(std::size_t(n - first));
    int32_t next = first;
    std::size_t u = 0;
    for (int32_t v = first; v < n; ++v) {
      const bool gone = u < unused.size() && unused[u] == v;
      u += gone ? 1 : 0;
      old_to_new[std::size_t(v - first)] = gone ? -1 : next++;
    }
    for (int32_t v = first + 1; v < n; ++v) {
      const int32_t to = old_to_new[std::size_t(v - first)];
      if (to >= 0) vs[std::size_t(to)] = vs[std::size_t(v)];
    }
    vs.resize(vs.size() - unused.size());
    // The triangles renumbered in parallel chunks (each triangle is written once, by one task).
    auto& triangles = m_object.surface.triangles;
    exec.parallel_for(int(triangles.size()), 16384, [&](int begin, int end) {
      for (int f = begin; f < end; ++f)
        for (int32_t& v : triangles[std::size_t(f)])
          if (v > first) v = old_to_new[std::size_t(v - first)];
    });
    m_compacted = true;
    return edit;
  }

  // Keeps the edits; the grid's triangles keep their indices and their vertices their positions.
  void commit() {
    m_editor.commit();
    m_committed = true;
    follow_bounds();
    m_object.grid.vertices = m_object.surface.vertices.size();
    m_object.grid.triangles = m_object.surface.triangles.size();
  }

 private:
  // The object, its grid over S built first when the caller did not build it (O(|S|)).
  static CutObject& indexed(CutObject& object) {
    if (!surface_indexed(object)) {
      try {
        index_surface(object);
      } catch (const std::invalid_argument& e) {
        throw StageFailure(std::string("surface: ") + e.what());
      }
    }
    return object;
  }

  // The grid's bounds of S after the cut, exactly, without a pass over S: S lost the vertices of m_unused that it had
  // before (nothing else moved) and gained the cut's kept new vertices, the last ones. While no lost vertex lies on
  // one of the bounds, each bound is still reached by a kept vertex, so the old bounds grown by the new vertices are
  // S's; otherwise they are dropped, for the next cut that needs them to compute.
  void follow_bounds() {
    std::optional<sim::Box3>& bounds = m_object.grid.bounds;
    if (!bounds) return;
    std::size_t lost = 0;
    for (std::size_t i = 0; i < m_unused.size(); ++i) {
      if (std::size_t(m_unused[i]) >= m_vertices_before) continue;
      ++lost;
      const sim::Vec3& p = m_unused_positions[i];
      if ((p.array() == bounds->min.array()).any() || (p.array() == bounds->max.array()).any()) {
        bounds.reset();
        return;
      }
    }
    const std::vector<sim::Vec3>& vs = m_object.surface.vertices;
    for (std::size_t v = m_vertices_before - lost; v < vs.size(); ++v) *bounds = grow(*bounds, {vs[v], vs[v]});
  }

  // Undoes compact(): the kept vertices move back up (back to front, so that none overwrites one not yet moved),
  // the unused ones come back, and the triangles get their old indices again.
  void uncompact() {
    std::vector<sim::Vec3>& vs = m_object.surface.vertices;
    const int32_t first = m_unused.front();
    const std::size_t n = vs.size() + m_unused.size();
    std::vector<int32_t> new_to_old;  // for the new indices from `first` on
    for (int32_t v = first, u = 0; v < int32_t(n); ++v) {
      if (std::size_t(u) < m_unused.size() && m_unused[std::size_t(u)] == v)
        ++u;
      else
        new_to_old.push_back(v);
    }
    for (auto& t : m_object.surface.triangles)
      for (int32_t& v : t)
        if (v >= first) v = new_to_old[std::size_t(v - first)];
    vs.resize(n);
    std::size_t u = m_unused.size();
    for (int32_t v = int32_t(n) - 1; v >= first; --v) {
      if (u > 0 && m_unused[u - 1] == v) {
        vs[std::size_t(v)] = m_unused_positions[--u];
      } else {
        vs[std::size_t(v)] = vs[std::size_t(v) - u];
      }
    }
    m_compacted = false;
  }

  CutObject& m_object;  ///< declared first: indexed before the editor is made
  SurfaceEditor m_editor;
  std::size_t m_vertices_before;            ///< S.vertices[0, m_vertices_before) are those S had before the cut
  bool m_committed = false;
  bool m_compacted = false;
  std::vector<int32_t> m_unused;            ///< compact(): the vertices it removed, ascending
  std::vector<sim::Vec3> m_unused_positions;  ///< compact(): their positions, m
};

// What stage 2 did to S.
struct SurfaceCut {
  std::vector<int32_t> unused;     ///< vertices of S that no triangle uses any more, ascending
  bool changed = false;            ///< S changed
  std::vector<char> unrestricted;  ///< per blade: its restriction was dropped
};

// S \ B'_k through the editor, for blade k of `rest` (moved in place when it had to be perturbed). The restriction
// decides per region of S and of the blade, by one point each, and leaves are coarser than S: where a region
// straddles the border of the foreign material, the kept pieces need not close up and the boolean refuses its
// result. B'_k then cuts without the restriction (as if nothing were foreign), cut.unrestricted[k] says so, and the
// model stages must run again without it too. Throws StageFailure when the boolean fails.
SurfaceEditResult cut_with_blade(SurfaceEditor& editor, const sim::ObjectModel& model, RestBlades& rest,
                                 std::size_t k, SurfaceCutOptions& sopt, SurfaceCut& cut, CutOutcome& out) {
  sim::TriMesh& b = rest.blades[k];
  sopt.removable = nullptr;
  if (!rest.foreign[k].empty())
    sopt.removable = [&model, &f = rest.foreign[k]](const sim::Vec3& p) { return !in_foreign(model, f, p); };
  // A degenerate configuration that the boolean refuses is retried with the blade moved by 1e-9, 1e-7, 1e-5 of its
  // size; the blade that was used is the one the model stages must use too. A failed attempt leaves S as it was.
  auto [r, moves] = cut_surface_in_place_perturbing(editor, b, sopt);
  if (r.status == SurfaceCutStatus::failed && sopt.removable) {
    sopt.removable = nullptr;
    sim::TriMesh unrestricted_blade = b;
    auto [again, again_moves] = cut_surface_in_place_perturbing(editor, unrestricted_blade, sopt);
    if (again.status != SurfaceCutStatus::failed) {
      b = std::move(unrestricted_blade);
      r = std::move(again);
      moves = again_moves;
      cut.unrestricted[k] = 1;
      ++out.unrestricted;
      --out.restricted_components;
    }
  }
  if (moves > 0) {
    ++out.perturbed;
    out.blade_shift = std::max(out.blade_shift, blade_shift_fraction(moves));
  }
  if (r.status == SurfaceCutStatus::failed) throw StageFailure("surface: " + r.reason);
  return std::move(r);
}

// Whether rest blade k, unrestricted, is the same as an earlier blade of this cut that cut unrestricted (both
// snapped to one, snap_blade): S \ B \ B = S \ B, and the second boolean would only meet the walls the first made.
bool repeats_unrestricted(const RestBlades& rest, const SurfaceCut& cut, std::size_t k) {
  if (!rest.foreign[k].empty()) return false;
  const sim::TriMesh& b = rest.blades[k];
  for (std::size_t j = 0; j < k; ++j)
    if ((rest.foreign[j].empty() || cut.unrestricted[j]) && same_mesh(rest.blades[j], b)) return true;
  return false;
}

// Stage 2: S <- S \ B'_i for each rest blade in turn, in place (the editor journals the edits).
SurfaceCut surface_stage(SurfaceEditor& editor, const CutObject& object, const sim::ObjectModel& model,
                         RestBlades& rest, const CutOptions& options, CutOutcome& out) {
  SurfaceCut cut;
  cut.unrestricted.assign(rest.blades.size(), 0);
  SurfaceCutOptions sopt;
  sopt.verify = options.verify;
  sopt.tiny_edge = kTinyEdgeFraction * options.min_feature;
  sopt.check_blade_self_intersection = false;  // blades are checked when loaded (or built convex)
  // S checked once, and changed since only by verified cuts (which check every changed face against its
  // neighbours), stays free of self-intersections: CGAL need not check it again.
  sopt.check_surface_self_intersection = !object.surface_checked;
  for (std::size_t k = 0; k < rest.blades.size(); ++k) {
    if (editor.mesh().triangles.empty()) break;
    if (repeats_unrestricted(rest, cut, k)) continue;
    const SurfaceEditResult r = cut_with_blade(editor, model, rest, k, sopt, cut, out);
    if (r.status == SurfaceCutStatus::no_op) continue;
    out.removed_volume += r.removed_volume;
    out.collapses += r.collapses;
    if (r.new_triangles > 0) {
      const bool first = out.new_triangles == 0;
      out.min_angle_deg = first ? r.min_angle_deg : std::min(out.min_angle_deg, r.min_angle_deg);
      out.min_edge = first ? r.min_edge : std::min(out.min_edge, r.min_edge);
      out.new_triangles += r.new_triangles;
    }
    std::vector<int32_t> merged;
    merged.reserve(cut.unused.size() + r.removed_vertices.size());
    std::merge(cut.unused.begin(), cut.unused.end(), r.removed_vertices.begin(), r.removed_vertices.end(),
               std::back_inserter(merged));
    cut.unused = std::move(merged);
    cut.changed = true;
  }
  return cut;
}

// The surface parts that lie in the removed fragments go with them: each component of S whose vertices mostly lie
// in the leaves `fragment_leaves` of `split` (the model before the fragments went). When S changes, cut.unused
// lists again every vertex that no triangle uses.
void remove_fragment_surface(SurfaceEditor& editor, const sim::ObjectModel& split,
                             const std::vector<int>& fragment_leaves, SurfaceCut& cut) {
  std::vector<char> gone_leaf(std::size_t(split.num_elements()), 0);
  for (int e : fragment_leaves) gone_leaf[std::size_t(e)] = 1;
  int ncomp = 0;
  const sim::TriMesh& current = editor.mesh();
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
  if (drop.empty()) return;
  editor.remove_faces(drop);
  std::vector<char> used(current.vertices.size(), 0);
  for (const auto& t : current.triangles)
    for (int32_t v : t) used[std::size_t(v)] = 1;
  cut.unused.clear();
  for (std::size_t v = 0; v < used.size(); ++v)
    if (!used[v]) cut.unused.push_back(int32_t(v));
  cut.changed = true;
}

// ---- 5. embedding, then the solver ---------------------------------------------------------------------------------

// Nothing is left to simulate: the object is gone. S's edits are kept and S is emptied; the simulator drops its model
// (sim::Simulator::remove_object: an empty model, time still runs).
void commit_removed(CutObject& object, sim::Simulator& simulator, SurfaceTransaction& surface) {
  surface.commit();
  object.surface = sim::TriMesh{};
  object.grid = SurfaceGrid{};
  object.cut_faces.clear();
  simulator.remove_object();
}

// The solver part of stage 5: the simulator takes the new revision as the model thread prepared it (joined first),
// or, should the preparation have failed, sets it and refreshes its solver here (a failed analysis is the next
// step's to handle). Returns the stage's ms, the model thread's preparation included but not the first step's bridge
// solve it prepared, which goes to `bridge_ms`.
double adopt_model(sim::Simulator& simulator, ModelStages& stages, double& bridge_ms) {
  ModelWork& work = stages.finished();
  const auto t0 = Clock::now();
  if (work.have_prepared) {
    bridge_ms = work.prepared.bridge_ms();
    simulator.adopt(std::move(work.prepared));
    return work.ms_prepare - bridge_ms + ms_since(t0);
  }
  simulator.set_model(*work.next);
  try {
    simulator.refresh_solver();
  } catch (const std::exception&) {
  }
  return ms_since(t0);
}

// Whether every rest-space blade would remove only material within options.min_feature of its surface (a sub-feature
// shell, which the cut keeps whole: removes_only_subfeature). Indexes S when it has no grid yet (throws StageFailure
// when S is invalid).
bool only_subfeature(CutObject& object, const RestBlades& rest, const CutOptions& options) {
  if (!(options.min_feature > 0.0)) return false;
  if (!surface_indexed(object)) {
    try {
      index_surface(object);
    } catch (const std::invalid_argument& e) {
      throw StageFailure(std::string("surface: ") + e.what());
    }
  }
  return std::all_of(rest.blades.begin(), rest.blades.end(), [&](const sim::TriMesh& b) {
    return removes_only_subfeature(object.surface, *object.grid.grid, b, options.min_feature);
  });
}

// Keeps the rest-space blades of a cut that changed S for the next cuts to snap to (at most kRecentBlades, the
// oldest dropped first), each with whether it removed all the material under it (no foreign leaves, or its
// restriction dropped); one that snapped is there already, and becomes whole when it is now.
void remember_blades(CutObject& object, const RestBlades& rest) {
  if (!(object.surface.triangles.size() > 0)) return;
  std::vector<sim::TriMesh>& recent = object.recent_blades;
  std::vector<char>& whole = object.recent_whole;
  whole.resize(recent.size(), 0);
  for (std::size_t k = 0; k < rest.blades.size(); ++k) {
    const sim::TriMesh& b = rest.blades[k];
    const char now_whole = rest.foreign[k].empty() ? 1 : 0;
    const auto known =
        std::find_if(recent.begin(), recent.end(), [&](const sim::TriMesh& e) { return same_mesh(e, b); });
    if (known != recent.end()) {
      whole[std::size_t(known - recent.begin())] |= now_whole;
      continue;
    }
    if (recent.size() >= kRecentBlades) {
      recent.erase(recent.begin());
      whole.erase(whole.begin());
    }
    recent.push_back(b);
    whole.push_back(now_whole);
  }
}

// Whether every rest-space blade of the cut is one that an earlier cut applied to all the material under it
// (CutObject::recent_whole): S then holds no material inside any of them (material never returns in rest space),
// and the boolean would only meet the walls they left, coincident face on face, at the cost of exact arithmetic.
bool repeats_whole_cuts(const CutObject& object, const RestBlades& rest) {
  if (rest.blades.empty() || object.recent_whole.size() != object.recent_blades.size()) return false;
  return std::all_of(rest.blades.begin(), rest.blades.end(), [&](const sim::TriMesh& b) {
    for (std::size_t j = 0; j < object.recent_blades.size(); ++j)
      if (object.recent_whole[j] && same_mesh(object.recent_blades[j], b)) return true;
    return false;
  });
}

// How a cut ended when it did not throw.
struct Verdict {
  std::string status;  ///< "ok" | "no-op"
  std::string reason;  ///< why a no-op
};

// The stages of apply_cut after its checks (see there), with their figures in `out`. Throws StageFailure (or
// another exception) to skip the cut; the transaction then leaves everything as it was.
Verdict run_cut(CutObject& object, sim::Simulator& simulator, sim::SurfaceEmbedding& embedding,
                const CutRequest& request, const CutOptions& options, CutOutcome& out) {
  const sim::ObjectModel& model = simulator.model();
  auto t0 = Clock::now();
  RestBlades rest = back_transform(object, model, simulator.state(), request, options, out);
  out.ms.back_transform = ms_since(t0);
  if (rest.blades.empty()) return {"no-op", "the blade meets no element"};
  if (repeats_whole_cuts(object, rest)) {
    out.ms.surface = ms_since(t0) - out.ms.back_transform;
    return {"no-op", "the blade is an earlier cut's, which removed all the material under it"};
  }
  if (only_subfeature(object, rest, options)) {
    out.ms.surface = ms_since(t0) - out.ms.back_transform;
    return {"no-op", "the blade would remove only a shell of material thinner than cutting.min_feature (kept whole)"};
  }

  ModelStages stages(simulator, options, request.inscribed_radius, rest);
  t0 = Clock::now();
  SurfaceTransaction surface(object);
  SurfaceCut cut = surface_stage(surface.editor(), object, model, rest, options, out);
  out.ms.surface = ms_since(t0);
  stages.surface_done();

  ModelWork& work = model_stages_done(stages, rest, cut.unrestricted, out);
  if (work.dead_empty && !cut.changed) return {"no-op", "the blade removes no material"};
  if (!work.fragment_leaves.empty()) {
    t0 = Clock::now();
    remove_fragment_surface(surface.editor(), *work.before_fragments, work.fragment_leaves, cut);
    out.ms.node_split += ms_since(t0);
  }

  t0 = Clock::now();
  if (work.all_gone) {
    commit_removed(object, simulator, surface);
    out.ms.embedding = ms_since(t0);
    return {"ok", ""};
  }
  // S compacted once, in place; the embedding follows it (strong guarantee: when it throws, it is unchanged and the
  // transaction restores S).
  const sim::SurfaceEdit edit = surface.compact(cut.unused, simulator.executor());
  embedding.update(*work.next, object.surface, edit, &simulator.executor());
  out.ms.embedding = ms_since(t0);
  out.ms.solver_update = adopt_model(simulator, stages, out.ms.bridge);
  surface.commit();
  object.surface_checked = object.surface_checked && options.verify;
  remember_blades(object, rest);
  return {"ok", ""};
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
  object.grid.bounds.reset();
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
  if (simulator.empty()) return finish("no-op", "the object has been cut away entirely");
  if (!simulator.model().material_graph()) return finish("skipped", "the object has no material graph");
  if (!(request.inscribed_radius > 0.0) || !std::isfinite(request.inscribed_radius))
    return finish("skipped", "the blade has no positive inscribed radius");
  try {
    Verdict v = run_cut(object, simulator, embedding, request, options, out);
    return finish(std::move(v.status), std::move(v.reason));
  } catch (const StageFailure& e) {
    return finish("skipped", e.what());
  } catch (const std::exception& e) {
    return finish("skipped", std::string("unexpected error: ") + e.what());
  }
}

}  // namespace octocut::cutting
