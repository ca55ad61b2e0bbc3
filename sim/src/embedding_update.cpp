// The update after a cut (SPEC §2.4, paper §4.5): the Z-curve list is edited, the kept vertices keep their leaves
// (renumbered) and their composed rows where the new revision leaves the rows of P alone, and only the new vertices,
// those of new or changed leaves and the fallback ones are embedded again.
#include <algorithm>
#include <bit>
#include <functional>
#include <numeric>
#include <stdexcept>
#include <string>

#include "embedding_internal.hpp"
#include "octocut/sim/embedding.hpp"

namespace octocut::sim {

namespace {

// For each leaf of `old_tree`, its index in `tree` when the same cell is a leaf there, else -1. Both trees are in
// Morton order, so one merge pass suffices.
std::vector<int> match_leaves(const Octree& old_tree, const Octree& tree, std::vector<char>& kept_new) {
  std::vector<int> old_to_new(std::size_t(old_tree.size()), -1);
  kept_new.assign(std::size_t(tree.size()), 0);
  int i = 0, j = 0;
  while (i < old_tree.size() && j < tree.size()) {
    const std::uint64_t ci = old_tree.leaf(i).morton(), cj = tree.leaf(j).morton();
    if (ci == cj) {
      if (old_tree.leaf(i).level == tree.leaf(j).level) {
        old_to_new[std::size_t(i)] = j;
        kept_new[std::size_t(j)] = 1;
      }
      ++i;
      ++j;
    } else if (ci < cj) {
      ++i;
    } else {
      ++j;
    }
  }
  return old_to_new;
}

// Old-to-new DOF map by logical node: the r-th DOF of a node in the old DOF list goes to the r-th DOF of the same
// node in the new one, -1 where the new list has none (|old|). `old_node`, `new_node`: node key of each DOF. DOF maps
// number their DOFs by node key, then by component, so the map is strictly increasing on the DOFs it maps; should
// either list not be sorted by node, nothing is mapped (all -1), which only costs speed.
std::vector<int> match_dofs(std::span<const std::uint64_t> old_node, std::span<const std::uint64_t> new_node) {
  std::vector<int> map(old_node.size(), -1);
  if (!std::is_sorted(old_node.begin(), old_node.end()) || !std::is_sorted(new_node.begin(), new_node.end()))
    return map;
  std::size_t i = 0, j = 0;
  while (i < old_node.size() && j < new_node.size()) {
    if (old_node[i] < new_node[j]) {
      ++i;
    } else if (new_node[j] < old_node[i]) {
      ++j;
    } else {
      // The DOFs of one node on both sides, paired in order.
      const std::uint64_t key = old_node[i];
      for (; i < old_node.size() && j < new_node.size() && old_node[i] == key && new_node[j] == key; ++i, ++j)
        map[i] = int(j);
      while (i < old_node.size() && old_node[i] == key) ++i;
      while (j < new_node.size() && new_node[j] == key) ++j;
    }
  }
  return map;
}

// True when the 8 rows of P for old leaf i (old_begin, old_dof, old_weight: the CSR of the old P) and for new leaf j
// hold the same entries in the same order, every old DOF mapped by dof_map onto the new one and the weights equal
// bit for bit. A vertex bound to the leaf with the same weights then composes to its old row, renumbered.
bool same_leaf_rows(std::span<const int> old_begin, std::span<const int> old_dof, std::span<const double> old_weight,
                    int i, const DofMap& P, int j, std::span<const int> dof_map) {
  const std::size_t a0 = std::size_t(old_begin[8 * std::size_t(i)]), a1 = std::size_t(old_begin[8 * std::size_t(i) + 8]);
  const std::size_t b0 = std::size_t(P.slot_begin[8 * std::size_t(j)]);
  if (a1 - a0 != std::size_t(P.slot_begin[8 * std::size_t(j) + 8]) - b0) return false;
  for (int k = 1; k < 8; ++k)
    if (std::size_t(old_begin[8 * std::size_t(i) + std::size_t(k)]) - a0 !=
        std::size_t(P.slot_begin[8 * std::size_t(j) + std::size_t(k)]) - b0)
      return false;
  for (std::size_t n = 0; n < a1 - a0; ++n) {
    if (dof_map[std::size_t(old_dof[a0 + n])] != P.slot_dof[b0 + n]) return false;
    if (std::bit_cast<std::uint64_t>(old_weight[a0 + n]) != std::bit_cast<std::uint64_t>(P.slot_weight[b0 + n]))
      return false;
  }
  return true;
}

}  // namespace

struct SurfaceEmbedding::KeptLeaves {
  bool same_tree = false;         ///< the new tree has the old leaves (nothing to match)
  std::vector<int> old_to_new;    ///< each old leaf's index in the new tree, or -1 (old num_leaves)
  std::vector<char> kept_new;     ///< 1 for a new leaf that was a leaf before (new num_leaves; empty if same_tree)
  std::vector<int> dof_map;       ///< old DOF to new DOF by node, -1 for none (old num_dofs)
  std::vector<char> same_rows;    ///< 1 for a kept leaf whose 8 rows of P are the old ones up to dof_map (new leaves)
};

std::vector<int> SurfaceEmbedding::update(const ObjectModel& new_model, const TriMesh& surface,
                                          const SurfaceEdit& edit, Executor* exec) {
  // Validate everything before touching any member but scratch, so that a bad edit leaves the embedding as it was.
  check_update(new_model, surface, edit);
  const std::size_t nv_old = m_embedding.size(), nv_new = surface.vertices.size();
  const auto inserted = std::size_t(edit.inserted);

  // Two independent parts side by side: (a) the Z-curve list (delete, renumber, insert; the new vertices are the
  // last ones of S), what the new revision keeps (leaves, and rows of P up to the DOF renumbering), and the vertices
  // to re-embed, each listed once in m_redo_list: the new ones, the fallback ones, those whose leaf is gone, and
  // those of new or changed leaves (m_reuse_from: the old vertex whose composed row a vertex keeps, or -1); (b) the
  // new triangles' adjacency (the triangles were validated above, so (b) cannot fail).
  std::vector<int> map;
  KeptLeaves kept;
  auto vertices = [&] {
    map = m_zcurve.update(edit.removed_vertices, std::span<const Vec3>(surface.vertices).subspan(nv_new - inserted));
    kept = match_kept_leaves(new_model);
    m_redo.assign(nv_new, 0);
    m_redo_list.clear();
    m_reuse_from.resize(nv_new);
    std::size_t first_removed = nv_old;
    for (const int v : edit.removed_vertices) first_removed = std::min(first_removed, std::size_t(v));
    move_kept_vertices(map, first_removed, inserted, kept);
    flag_leaves(new_model.tree(), kept, edit.changed_leaves);
    std::sort(m_redo_list.begin(), m_redo_list.end());
    fallback_hints(map, kept);
  };
  auto adjacency = [&] { build_adjacency(surface.triangles, nv_new); };
  if (exec && exec->threads() > 1) {
    exec->parallel_for(2, 1, [&](int begin, int end) {
      for (int part = begin; part < end; ++part) (part == 0 ? std::function<void()>(vertices) : adjacency)();
    });
  } else {
    vertices();
    adjacency();
  }

  // Swap in the new tree, re-embed the flagged vertices, and compose: kept rows renumbered, the others anew through
  // the new P.
  if (!kept.same_tree) m_tree = new_model.tree();
  embed(new_model, surface, m_redo_list, false, exec, m_hints, kept.kept_new);
  compose(new_model.dofs(), m_reuse_from, kept.dof_map);
  m_last_reembedded = int(m_redo_list.size());
  return map;
}

void SurfaceEmbedding::rebind(const ObjectModel& new_model, const TriMesh& surface) {
  check_matches(surface, "SurfaceEmbedding::rebind");
  update(new_model, surface, SurfaceEdit{});
}

void SurfaceEmbedding::check_update(const ObjectModel& new_model, const TriMesh& surface, const SurfaceEdit& edit) {
  if (new_model.root().min != m_root.min || new_model.root().size != m_root.size)
    throw std::invalid_argument("SurfaceEmbedding::update: the new model has another root cube");
  if (new_model.tree().size() == 0) throw std::invalid_argument("SurfaceEmbedding::update: the new model has no leaf");
  const std::size_t nv_old = m_embedding.size();
  detail::check_index_list(edit.removed_vertices, nv_old, "removed_vertices");
  // S after the edit: the kept vertices, then the inserted ones.
  const std::size_t kept = nv_old - edit.removed_vertices.size();
  if (edit.inserted < 0 || surface.vertices.size() != kept + std::size_t(edit.inserted))
    throw std::invalid_argument("SurfaceEmbedding::update: the surface has " + std::to_string(surface.vertices.size()) +
                                " vertices, not the " + std::to_string(kept) + " kept and " +
                                std::to_string(edit.inserted) + " inserted");
  detail::check_finite(std::span<const Vec3>(surface.vertices).subspan(kept), "inserted vertex");
  for (std::size_t i = 0; i < edit.changed_leaves.size(); ++i) {
    const int l = edit.changed_leaves[i];
    if (l < 0 || l >= new_model.tree().size())
      throw std::invalid_argument("changed_leaves[" + std::to_string(i) + "] = " + std::to_string(l) +
                                  " is out of range [0, " + std::to_string(new_model.tree().size()) + ")");
  }
  // The triangles are validated while their corners are counted for the adjacency (into scratch).
  count_corners(surface.triangles, surface.vertices.size());
}

SurfaceEmbedding::KeptLeaves SurfaceEmbedding::match_kept_leaves(const ObjectModel& new_model) const {
  // Leaves kept from the old tree keep their vertices' weights, renumbered (nothing to match when the tree is the
  // same).
  const Octree& tree = new_model.tree();
  const DofMap& P = new_model.dofs();
  KeptLeaves kept;
  kept.same_tree = tree.leaves() == m_tree.leaves();
  if (kept.same_tree) {
    kept.old_to_new.resize(std::size_t(m_tree.size()));
    std::iota(kept.old_to_new.begin(), kept.old_to_new.end(), 0);
  } else {
    kept.old_to_new = match_leaves(m_tree, tree, kept.kept_new);
  }
  // Kept leaves whose 8 rows of P are the same up to the renumbering of the DOFs (most of them: a cut rebuilds the
  // DOFs only around the changed region); their regularly bound vertices keep their composed rows.
  kept.dof_map = match_dofs(m_dof_node, P.dof_node);
  kept.same_rows.assign(std::size_t(tree.size()), 0);
  for (int i = 0; i < m_tree.size(); ++i) {
    const int j = kept.old_to_new[std::size_t(i)];
    if (j >= 0)
      kept.same_rows[std::size_t(j)] =
          same_leaf_rows(m_slot_begin, m_slot_dof, m_slot_weight, i, P, j, kept.dof_map);
  }
  return kept;
}

void SurfaceEmbedding::flag(std::size_t k) {
  if (!m_redo[k]) {
    m_redo[k] = 1;
    m_redo_list.push_back(int(k));
  }
  m_reuse_from[k] = -1;
}

void SurfaceEmbedding::move_kept_vertices(std::span<const int> map, std::size_t first_removed, std::size_t inserted,
                                          const KeptLeaves& kept) {
  const std::size_t nv_old = map.size(), nv_new = m_redo.size();
  // Kept vertex k (old index v), already moved to k: its new leaf, or the flag.
  auto rebind_kept = [&](std::size_t k, std::size_t v) {
    VertexEmbedding& e = m_embedding[k];
    const int leaf = e.fallback ? -1 : kept.old_to_new[std::size_t(e.leaf)];
    if (leaf < 0) {
      flag(k);
      return;
    }
    if (e.leaf != leaf) e.leaf = leaf;
    m_reuse_from[k] = kept.same_rows[std::size_t(leaf)] ? int(v) : -1;
  };
  // Room for the next cuts too (one reallocation now instead of one per cut).
  if (nv_new > m_embedding.capacity()) m_embedding.reserve(nv_new + nv_new / 8);
  // Before the first removed vertex nothing moves.
  for (std::size_t v = 0; v < first_removed; ++v) rebind_kept(v, v);
  // After it, the runs between removed vertices move down, a cache-sized chunk at a time.
  constexpr std::size_t kChunk = 512;
  std::size_t k = first_removed;
  for (std::size_t v = first_removed; v < nv_old;) {
    if (map[v] < 0) {
      ++v;
      continue;
    }
    std::size_t end = v + 1;
    while (end < nv_old && end - v < kChunk && map[end] >= 0) ++end;
    std::copy(m_embedding.begin() + std::ptrdiff_t(v), m_embedding.begin() + std::ptrdiff_t(end),
              m_embedding.begin() + std::ptrdiff_t(k));
    for (std::size_t u = v; u < end; ++u) rebind_kept(k + (u - v), u);
    k += end - v;
    v = end;
  }
  // The inserted vertices come after the kept ones.
  m_embedding.resize(nv_new);
  for (std::size_t i = nv_new - inserted; i < nv_new; ++i) flag(i);
}

void SurfaceEmbedding::fallback_hints(std::span<const int> map, const KeptLeaves& kept) {
  m_hints.clear();
  for (const auto& [v, a] : m_fallback_anchor) {
    const int k = map[std::size_t(v)];
    if (k < 0) continue;
    const int anchor = a >= 0 ? map[std::size_t(a)] : -1;
    if (a >= 0 && anchor < 0) continue;  // its anchor is gone: nothing to compare with
    // A fallback vertex keeps its old leaf index until it is re-embedded (move_kept_vertices).
    const int leaf = kept.old_to_new[std::size_t(m_embedding[std::size_t(k)].leaf)];
    const int reuse = leaf >= 0 && kept.same_rows[std::size_t(leaf)] ? v : -1;
    m_hints.push_back({k, leaf, anchor, reuse});
  }
}

void SurfaceEmbedding::flag_leaves(const Octree& tree, const KeptLeaves& kept, std::span<const int> changed) {
  // Two binary searches per leaf on the Z-curve list.
  auto flag_leaf = [&](int j) {
    for (const ZEntry& z : m_zcurve.in_cell(tree.leaf(j))) flag(std::size_t(z.vertex));
  };
  for (int j = 0; j < (kept.same_tree ? 0 : tree.size()); ++j)
    if (!kept.kept_new[std::size_t(j)]) flag_leaf(j);
  for (const int j : changed) flag_leaf(j);
}

}  // namespace octocut::sim
