#include "octocut/sim/object.hpp"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <numeric>
#include <span>
#include <stdexcept>

namespace octocut::sim {

namespace {

// A handle's keyframed motion at t (translation of the box, rotation about its centre). Before a first keyframe
// later than 0 the handle moves from its rest pose at t = 0: an implicit identity keyframe there.
Pose handle_motion(std::span<const PoseKeyframe> keys, double t) {
  if (keys.front().t > 0.0 && t < keys.front().t) {
    const std::array<PoseKeyframe, 2> from_rest{PoseKeyframe{}, keys.front()};
    return interpolate_pose(from_rest, t);
  }
  return interpolate_pose(keys, t);
}

// The boxes where a cut changed the material: a leaf is touched when its closed box meets one of them, grown by a
// round-off margin `eps` (m), so that a change that only reaches a leaf's face still redoes that face.
class ChangedRegion {
 public:
  ChangedRegion(const std::vector<Box3>& changed, double eps) : m_changed(changed), m_eps(eps) {
    if (changed.empty()) return;
    m_all = changed.front();  // bounding box of the changed boxes, for a quick reject
    for (const Box3& b : changed) {
      m_all.min = m_all.min.cwiseMin(b.min);
      m_all.max = m_all.max.cwiseMax(b.max);
    }
  }
  [[nodiscard]] bool touches(const Box3& box) const {
    return !m_changed.empty() && meets(box, m_all) &&
           std::any_of(m_changed.begin(), m_changed.end(), [&](const Box3& b) { return meets(box, b); });
  }

 private:
  [[nodiscard]] bool meets(const Box3& a, const Box3& b) const {
    return (a.min.array() <= b.max.array() + m_eps).all() && (b.min.array() <= a.max.array() + m_eps).all();
  }
  const std::vector<Box3>& m_changed;
  double m_eps;
  Box3 m_all;
};

}  // namespace

Vec3 HandleSpec::position(const Vec3& X, double t) const {
  if (keyframes.empty()) return X;
  const Pose motion = handle_motion(keyframes, t);
  const Vec3 c = 0.5 * (box.min + box.max);
  return c + motion.rotation * (X - c) + motion.position;
}

ObjectModel::ObjectModel()
    : m_material(std::make_shared<BoxSetMaterial>(std::vector<Box3>{})), m_unit_k(Mat24::Zero()) {
  m_dofs.slot_begin = {0};
}

ObjectModel ObjectModel::build(const OctreeSpec& spec, std::shared_ptr<const MaterialSource> material,
                               const MaterialParams& params, std::vector<HandleSpec> handles) {
  if (!material) throw std::invalid_argument("ObjectModel::build: no material");
  if (spec.base_level < 0 || spec.max_level > kMaxDepth || spec.base_level > spec.max_level)
    throw std::invalid_argument("ObjectModel::build: need 0 <= base_level <= max_level <= 20");
  ObjectModel m;
  m.m_root = spec.root;
  m.m_material = std::move(material);
  m.m_params = params;
  m.m_handles = std::move(handles);
  m.m_max_level = spec.max_level;

  // Target level of a cell: the base level, raised by every refine region it overlaps with positive volume.
  auto target = [&](const Box3& box) {
    int level = spec.base_level;
    for (const RefineSpec& r : spec.refine)
      if (box.overlap_volume(r.box) > 0.0) level = std::max(level, std::min(r.level, spec.max_level));
    return level;
  };

  // Depth-first subdivision from the root; empty cells are dropped with their whole subtree.
  std::vector<OccupiedCell> leaves;
  std::vector<Cell> stack{Cell{}};
  while (!stack.empty()) {
    const Cell c = stack.back();
    stack.pop_back();
    const Box3 box = m.m_root.cell_box(c);
    const double occ = m.m_material->occupancy(box);
    if (occ < kEmptyOccupancy) continue;
    if (c.level < target(box)) {
      for (int k = 7; k >= 0; --k) stack.push_back(c.child(k));
    } else {
      leaves.push_back({c, occ});
      // Refuse runaway levels before memory runs out: a bad level in a scene must be an error, not a hang.
      if (leaves.size() > kMaxElements)
        throw std::invalid_argument("the octree would exceed " + std::to_string(kMaxElements) +
                                    " elements; lower base_level or the refine levels");
    }
  }
  if (leaves.empty()) throw std::invalid_argument("ObjectModel::build: the material does not meet the octree root");

  m.set_leaves(std::move(leaves));
  m.finish(nullptr, {});
  return m;
}

ObjectModel ObjectModel::refined(const std::vector<int>& leaves) const {
  std::vector<char> split(std::size_t(num_elements()), 0);
  for (int i : leaves) {
    if (i < 0 || i >= num_elements()) throw std::out_of_range("ObjectModel::refined: leaf index out of range");
    if (m_tree.leaf(i).level < m_max_level) split[std::size_t(i)] = 1;
  }
  // Kept leaves keep their occupancy (the material is the same); children are measured once, here.
  std::vector<OccupiedCell> cells;
  cells.reserve(m_tree.leaves().size() + 7 * leaves.size());
  for (int i = 0; i < num_elements(); ++i) {
    const Cell& c = m_tree.leaf(i);
    if (!split[std::size_t(i)]) {
      cells.push_back({c, m_occupancy[std::size_t(i)]});
      continue;
    }
    for (int k = 0; k < 8; ++k) {
      const Cell ch = c.child(k);
      const double occ = m_material->occupancy(m_root.cell_box(ch));
      if (occ >= kEmptyOccupancy) cells.push_back({ch, occ});
    }
  }
  ObjectModel m = next_revision(m_material);
  m.set_leaves(std::move(cells));
  m.finish(this, {});
  return m;
}

ObjectModel ObjectModel::refined_where(const std::function<bool(const Cell&)>& split, int* refined) const {
  return refine_impl(split, nullptr, {}, refined);
}

ObjectModel ObjectModel::refined_with_material(const std::function<bool(const Cell&)>& split,
                                               std::shared_ptr<const MaterialSource> material,
                                               const std::vector<Box3>& changed, int* refined) const {
  if (!material) throw std::invalid_argument("ObjectModel::refined_with_material: no material");
  return refine_impl(split, std::move(material), changed, refined);
}

ObjectModel ObjectModel::refine_impl(const std::function<bool(const Cell&)>& split,
                                     std::shared_ptr<const MaterialSource> material,
                                     const std::vector<Box3>& changed, int* refined) const {
  const bool cut = material != nullptr;
  const ChangedRegion region(changed, 1e-9 * m_root.size);
  // Depth-first below each split leaf, children in Morton order, so the cells come out sorted. A cell that is split
  // is measured in the old material (it exists when it holds material before the cut), and an empty one goes with
  // its subtree. A final leaf that the cut touches is measured in the new material only: kept when it holds
  // material after the cut, which implies that it held some before (occupancy sums only shrink when tets go).
  std::vector<OccupiedCell> cells;
  std::vector<Cell> touched;
  cells.reserve(m_tree.leaves().size() + 64);
  int count = 0;
  std::vector<Cell> stack;
  auto final_leaf = [&](const Cell& c, double occ_before) {
    const Box3 box = m_root.cell_box(c);
    if (cut && region.touches(box)) {
      touched.push_back(c);
      const double occ = material->occupancy(box);
      if (occ >= kEmptyOccupancy) cells.push_back({c, occ});
      return;
    }
    if (occ_before < 0.0) occ_before = m_material->occupancy(box);
    if (occ_before >= kEmptyOccupancy) cells.push_back({c, occ_before});
  };
  for (int i = 0; i < num_elements(); ++i) {
    const Cell& c = m_tree.leaf(i);
    if (c.level >= m_max_level || !split(c)) {
      final_leaf(c, m_occupancy[std::size_t(i)]);
      continue;
    }
    ++count;
    stack.clear();
    for (int k = 7; k >= 0; --k) stack.push_back(c.child(k));
    while (!stack.empty()) {
      const Cell ch = stack.back();
      stack.pop_back();
      if (ch.level >= m_max_level || !split(ch)) {
        final_leaf(ch, -1.0);
        continue;
      }
      if (m_material->occupancy(m_root.cell_box(ch)) < kEmptyOccupancy) continue;
      ++count;
      for (int k = 7; k >= 0; --k) stack.push_back(ch.child(k));
    }
  }
  if (refined) *refined = count;
  if (!cut && count == 0) return *this;
  if (cells.empty()) throw std::invalid_argument("ObjectModel::with_material: no material is left in the octree");

  ObjectModel m = next_revision(cut ? std::move(material) : m_material);
  m.set_leaves(std::move(cells));
  m.finish(this, touched);
  return m;
}

ObjectModel ObjectModel::with_material(std::shared_ptr<const MaterialSource> material,
                                       const std::vector<Box3>& changed) const {
  if (!material) throw std::invalid_argument("ObjectModel::with_material: no material");
  // This model's occupancy and DOFs already follow its own material.
  if (material == m_material) {
    ObjectModel m = *this;
    m.m_revision = m_revision + 1;
    return m;
  }
  // A leaf is touched when its closed box meets a changed box (grown by a round-off margin), so that a change
  // that only reaches a leaf's face still redoes the connectivity across that face.
  const ChangedRegion region(changed, 1e-9 * m_root.size);

  // Touched leaves are measured anew and dropped when empty; every other leaf keeps its occupancy.
  std::vector<OccupiedCell> cells;
  std::vector<Cell> touched;
  cells.reserve(m_tree.leaves().size());
  for (int i = 0; i < num_elements(); ++i) {
    const Cell& c = m_tree.leaf(i);
    const Box3 box = m_root.cell_box(c);
    if (!region.touches(box)) {
      cells.push_back({c, m_occupancy[std::size_t(i)]});
      continue;
    }
    touched.push_back(c);
    const double occ = material->occupancy(box);
    if (occ >= kEmptyOccupancy) cells.push_back({c, occ});
  }
  if (cells.empty()) throw std::invalid_argument("ObjectModel::with_material: no material is left in the octree");

  ObjectModel m = next_revision(std::move(material));
  m.set_leaves(std::move(cells));
  m.finish(this, touched);
  return m;
}

ObjectModel ObjectModel::without_leaves(const std::vector<int>& leaves) const {
  std::vector<char> drop(std::size_t(num_elements()), 0);
  for (int i : leaves) {
    if (i < 0 || i >= num_elements()) throw std::out_of_range("ObjectModel::without_leaves: leaf index out of range");
    drop[std::size_t(i)] = 1;
  }
  std::vector<OccupiedCell> cells;
  cells.reserve(m_tree.leaves().size());
  for (int i = 0; i < num_elements(); ++i)
    if (!drop[std::size_t(i)]) cells.push_back({m_tree.leaf(i), m_occupancy[std::size_t(i)]});
  if (cells.empty()) throw std::invalid_argument("ObjectModel::without_leaves: every element would be removed");

  ObjectModel m = next_revision(m_material);
  m.set_leaves(std::move(cells));
  m.finish(this, {});
  return m;
}

ObjectModel ObjectModel::with_params(const MaterialParams& p) const {
  const bool finite = std::isfinite(p.young_modulus) && std::isfinite(p.poisson_ratio) && std::isfinite(p.density) &&
                      std::isfinite(p.rayleigh_mass) && std::isfinite(p.rayleigh_stiffness);
  if (!finite || p.young_modulus <= 0.0 || p.poisson_ratio < 0.0 || p.poisson_ratio >= 0.5 || p.density <= 0.0 ||
      p.rayleigh_mass < 0.0 || p.rayleigh_stiffness < 0.0)
    throw std::invalid_argument("ObjectModel::with_params: need E > 0, 0 <= nu < 0.5, density > 0 and damping >= 0");
  ObjectModel m = *this;
  m.m_params = p;
  m.m_revision = m_revision + 1;
  m.m_unit_k = unit_hex_stiffness(p.poisson_ratio, p.element);
  // Stiffness scale E phi h and lumped mass rho phi h^3 / 8 per slot, as finish() computes them.
  for (int e = 0; e < num_elements(); ++e)
    m.m_k_scale[std::size_t(e)] = p.young_modulus * m_occupancy[std::size_t(e)] * m_edge[std::size_t(e)];
  m.m_dof_mass.assign(std::size_t(m_dofs.num_dofs), 0.0);
  for (int s = 0; s < m_dofs.num_slots(); ++s) {
    const double h = m_edge[std::size_t(s / 8)];
    const double ms = p.density * m_occupancy[std::size_t(s / 8)] * h * h * h / 8.0;
    for (int i = m_dofs.slot_begin[std::size_t(s)]; i < m_dofs.slot_begin[std::size_t(s) + 1]; ++i)
      m.m_dof_mass[std::size_t(m_dofs.slot_dof[std::size_t(i)])] += m_dofs.slot_weight[std::size_t(i)] * ms;
  }
  return m;
}

ObjectModel ObjectModel::emptied() const { return next_revision(m_material); }

ObjectModel ObjectModel::next_revision(std::shared_ptr<const MaterialSource> material) const {
  ObjectModel m;
  m.m_root = m_root;
  m.m_material = std::move(material);
  m.m_params = m_params;
  m.m_handles = m_handles;
  m.m_max_level = m_max_level;
  m.m_revision = m_revision + 1;
  m.m_unit_k = m_unit_k;
  return m;
}

void ObjectModel::set_leaves(std::vector<OccupiedCell> cells) {
  // Octree keeps cells that come in Morton order as they are; sort here otherwise so occupancy stays aligned.
  auto by_code = [](const OccupiedCell& a, const OccupiedCell& b) { return a.cell.morton() < b.cell.morton(); };
  if (!std::is_sorted(cells.begin(), cells.end(), by_code)) std::sort(cells.begin(), cells.end(), by_code);
  std::vector<Cell> leaves;
  leaves.reserve(cells.size());
  m_occupancy.resize(cells.size());
  for (std::size_t i = 0; i < cells.size(); ++i) {
    leaves.push_back(cells[i].cell);
    m_occupancy[i] = cells[i].occupancy;
  }
  m_tree = Octree(std::move(leaves));
}

void ObjectModel::finish(const ObjectModel* previous, const std::vector<Cell>& material_changed) {
  const int ne = m_tree.size();
  if (!previous) m_unit_k = unit_hex_stiffness(m_params.poisson_ratio, m_params.element);

  // Per-element geometry and stiffness scale; the occupancy was set with the leaves.
  m_edge.resize(std::size_t(ne));
  m_k_scale.resize(std::size_t(ne));
  m_slot_rest.resize(8 * std::size_t(ne));
  for (int e = 0; e < ne; ++e) {
    const Cell& c = m_tree.leaf(e);
    const double h = m_root.cell_edge(c);
    m_edge[std::size_t(e)] = h;
    m_k_scale[std::size_t(e)] = m_params.young_modulus * m_occupancy[std::size_t(e)] * h;
    for (int k = 0; k < 8; ++k) m_slot_rest[8 * std::size_t(e) + std::size_t(k)] = m_root.to_world(c.corner(k));
  }

  // DOFs by node splitting and hard binding, redone locally around added, removed and material-changed leaves;
  // debug builds check the invariants of SPEC §2.3 on every revision.
  m_dofs = previous
               ? update_dof_map(previous->m_dofs, previous->m_tree, m_tree, m_root, *m_material, material_changed)
               : build_dof_map(m_tree, m_root, *m_material);
  assert(m_dofs.check_invariants().empty());

  // Lumped mass rho phi h^3 / 8 per slot, gathered to DOFs through P^T.
  m_dof_mass.assign(std::size_t(m_dofs.num_dofs), 0.0);
  for (int s = 0; s < m_dofs.num_slots(); ++s) {
    const int e = s / 8;
    const double h = m_edge[std::size_t(e)];
    const double ms = m_params.density * m_occupancy[std::size_t(e)] * h * h * h / 8.0;
    for (int i = m_dofs.slot_begin[std::size_t(s)]; i < m_dofs.slot_begin[std::size_t(s) + 1]; ++i)
      m_dof_mass[std::size_t(m_dofs.slot_dof[std::size_t(i)])] += m_dofs.slot_weight[std::size_t(i)] * ms;
  }

  // Handles: a DOF whose rest position lies in a handle's box follows the first such handle.
  const double eps = 1e-9 * m_root.size;
  m_dof_handle.assign(std::size_t(m_dofs.num_dofs), -1);
  for (int d = 0; d < m_dofs.num_dofs; ++d) {
    for (std::size_t h = 0; h < m_handles.size(); ++h) {
      if (m_handles[h].box.contains(m_dofs.dof_rest[std::size_t(d)], eps)) {
        m_dof_handle[std::size_t(d)] = int(h);
        break;
      }
    }
  }
}

Vec3 ObjectModel::handle_position(int dof, double t) const {
  const int h = m_dof_handle[std::size_t(dof)];
  const Vec3& X = m_dofs.dof_rest[std::size_t(dof)];
  return h < 0 ? X : m_handles[std::size_t(h)].position(X, t);
}

double ObjectModel::volume() const {
  double v = 0.0;
  for (int e = 0; e < num_elements(); ++e) v += m_occupancy[std::size_t(e)] * std::pow(m_edge[std::size_t(e)], 3);
  return v;
}

std::optional<PointEmbedding> ObjectModel::embed(const Vec3& rest) const {
  // Fixed-point coordinates on the finest grid, clamped into the root.
  const Vec3 g = (rest - m_root.min) / m_root.unit();
  if (!g.allFinite() || (g.array() < -1e-6).any() || (g.array() > double(kGridCells) + 1e-6).any())
    return std::nullopt;
  auto to_int = [](double v) {
    return std::uint32_t(std::clamp(std::floor(v), 0.0, double(kGridCells)));
  };
  const int leaf = m_tree.locate_point({to_int(g.x()), to_int(g.y()), to_int(g.z())});
  if (leaf < 0) return std::nullopt;
  const Box3 box = m_root.cell_box(m_tree.leaf(leaf));
  const Vec3 u = ((rest - box.min).array() / (box.max - box.min).array()).matrix().cwiseMax(0.0).cwiseMin(1.0);
  return PointEmbedding{leaf, trilinear_weights(u)};
}

Vec3 ObjectModel::evaluate(const PointEmbedding& e, const std::vector<Vec3>& slots) const {
  Vec3 p = Vec3::Zero();
  for (int k = 0; k < 8; ++k) p += e.weights[std::size_t(k)] * slots[8 * std::size_t(e.leaf) + std::size_t(k)];
  return p;
}

SimState SimState::rest(const ObjectModel& model) {
  SimState s;
  s.x = model.dofs().dof_rest;
  s.v.assign(s.x.size(), Vec3::Zero());
  return s;
}

DisjointSets element_groups(const ObjectModel& model, const std::vector<int>& elements) {
  const DofMap& dm = model.dofs();
  DisjointSets sets(elements.size());
  std::vector<int> owner(std::size_t(dm.num_dofs), -1);  // the first of `elements` (its index) that uses each DOF
  for (std::size_t i = 0; i < elements.size(); ++i) {
    for (int s = 8 * elements[i]; s < 8 * elements[i] + 8; ++s) {
      for (int k = dm.slot_begin[std::size_t(s)]; k < dm.slot_begin[std::size_t(s) + 1]; ++k) {
        int& o = owner[std::size_t(dm.slot_dof[std::size_t(k)])];
        if (o < 0) o = int(i);
        else sets.unite(o, int(i));
      }
    }
  }
  return sets;
}

std::vector<int> element_components(const ObjectModel& model, int& count) {
  const int ne = model.num_elements();
  std::vector<int> all(static_cast<std::size_t>(ne));
  std::iota(all.begin(), all.end(), 0);
  DisjointSets sets = element_groups(model, all);
  // Number the components by their smallest element (the root of each set).
  std::vector<int> comp(std::size_t(ne), -1), label(std::size_t(ne), -1);
  count = 0;
  for (int e = 0; e < ne; ++e) {
    int& l = label[std::size_t(sets.find(e))];
    if (l < 0) l = count++;
    comp[std::size_t(e)] = l;
  }
  return comp;
}

std::vector<ComponentInfo> component_info(const ObjectModel& model, const std::vector<int>& comp, int count) {
  if (comp.size() != std::size_t(model.num_elements()))
    throw std::invalid_argument("component_info: need one component per element");
  const DofMap& dm = model.dofs();
  std::vector<ComponentInfo> info(std::size_t(std::max(count, 0)));
  for (int e = 0; e < model.num_elements(); ++e) {
    const int c = comp[std::size_t(e)];
    if (c < 0 || c >= count) throw std::out_of_range("component_info: component index out of range");
    ComponentInfo& ci = info[std::size_t(c)];
    ++ci.elements;
    ci.volume += model.occupancy()[std::size_t(e)] * std::pow(model.edge()[std::size_t(e)], 3);
    for (int i = dm.slot_begin[8 * std::size_t(e)]; i < dm.slot_begin[8 * std::size_t(e) + 8]; ++i)
      if (model.dof_handle()[std::size_t(dm.slot_dof[std::size_t(i)])] >= 0) ci.anchored = true;
  }
  return info;
}

namespace {
// Where new DOF d of `to` takes its value from in `from` (see transfer_state): the old leaf and the trilinear weights
// of its 8 slots at the DOF's node; leaf -1 when no old leaf holds the node.
struct TransferSource {
  int leaf = -1;
  std::array<double, 8> w{};
};
TransferSource transfer_source(const ObjectModel& from, const ObjectModel& to, int d) {
  const DofMap& dm = to.dofs();
  // The old leaf that contains the new DOF's own leaf interpolates the old field at the DOF's node.
  const int slot = dm.dof_slot[std::size_t(d)];
  const Cell& leaf = to.tree().leaf(slot / 8);
  int old = from.tree().locate_cell(leaf.anchor);
  if (old >= 0 && from.tree().leaf(old).level > leaf.level) old = -1;
  const GridPoint n = node_from_key(dm.dof_node[std::size_t(d)]);
  if (old < 0) old = from.tree().locate_point(n);
  TransferSource src;
  if (old < 0) return src;
  src.leaf = old;
  src.w = trilinear_weights(from.tree().leaf(old).local(n).cwiseMax(0.0).cwiseMin(1.0));
  return src;
}
}  // namespace

SimState transfer_state(const ObjectModel& from, const SimState& state, const ObjectModel& to) {
  std::vector<Vec3> xs, vs;
  from.dofs().prolong(state.x, xs);
  from.dofs().prolong(state.v, vs);

  SimState out;
  out.t = state.t;
  const DofMap& dm = to.dofs();
  out.x.resize(std::size_t(dm.num_dofs));
  out.v.resize(std::size_t(dm.num_dofs));
  for (int d = 0; d < dm.num_dofs; ++d) {
    const TransferSource src = transfer_source(from, to, d);
    if (src.leaf < 0) {
      out.x[std::size_t(d)] = dm.dof_rest[std::size_t(d)];
      out.v[std::size_t(d)] = Vec3::Zero();
      continue;
    }
    Vec3 x = Vec3::Zero(), v = Vec3::Zero();
    for (int k = 0; k < 8; ++k) {
      x += src.w[std::size_t(k)] * xs[8 * std::size_t(src.leaf) + std::size_t(k)];
      v += src.w[std::size_t(k)] * vs[8 * std::size_t(src.leaf) + std::size_t(k)];
    }
    out.x[std::size_t(d)] = x;
    out.v[std::size_t(d)] = v;
  }
  return out;
}

SpMat transfer_matrix(const ObjectModel& from, const ObjectModel& to) {
  const DofMap& old = from.dofs();
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(std::size_t(to.num_dofs()) * 8);
  for (int d = 0; d < to.num_dofs(); ++d) {
    const TransferSource src = transfer_source(from, to, d);
    if (src.leaf < 0) continue;
    for (int k = 0; k < 8; ++k) {
      if (src.w[std::size_t(k)] == 0.0) continue;
      const std::size_t slot = 8 * std::size_t(src.leaf) + std::size_t(k);
      for (int i = old.slot_begin[slot]; i < old.slot_begin[slot + 1]; ++i)
        t.emplace_back(d, old.slot_dof[std::size_t(i)], src.w[std::size_t(k)] * old.slot_weight[std::size_t(i)]);
    }
  }
  SpMat T(to.num_dofs(), from.num_dofs());
  T.setFromTriplets(t.begin(), t.end());  // sums the weights of an old DOF reached through several slots
  return T;
}

}  // namespace octocut::sim
