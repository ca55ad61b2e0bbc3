// Phase 3 of the surface boolean S \ B' (surface_cut_phases.hpp): the kept pieces written back into S in place,
// through the journaled SurfaceEditor (which keeps the grid up to date). No CGAL.
//
// P's original vertices keep their indices; new vertices are matched between the two meshes by identical coordinates
// and appended; the pieces fill the changing faces' slots and the rest are appended, or the leftover slots removed.
// V(S) - V(S') is summed over the changed faces only.
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <unordered_map>
#include <vector>

#include "surface_cut_phases.hpp"

namespace octocut::cutting::surface_cut_detail {
namespace {

using sim::Vec3;

// Signed volume contribution of triangle abc relative to origin o (divergence theorem), m^3.
double tet_volume(const Vec3& o, const Vec3& a, const Vec3& b, const Vec3& c) {
  return (a - o).dot((b - o).cross(c - o)) / 6.0;
}

// The volume term (m^3) of triangle t of `mesh` relative to `centre` (m).
double tet_volume(const Vec3& centre, const sim::TriMesh& mesh, const Tri& t) {
  return tet_volume(centre, mesh.vertices[static_cast<std::size_t>(t[0])],
                    mesh.vertices[static_cast<std::size_t>(t[1])], mesh.vertices[static_cast<std::size_t>(t[2])]);
}

// Node ids, one numbering of the vertices of both corefined meshes: old vertex o of S -> o; new P vertex k
// (k >= |Patch::vertices|) -> nv + (k - |Patch::vertices|); blade vertex -> the P vertex with identical coordinates,
// else nv + n_new_p + its blade index.
struct Nodes {
  int32_t nv = 0;                // |V| of S before the cut
  int32_t n_new_p = 0;           // the vertices the corefinement added to P
  std::vector<int32_t> p_node;   // (|V_P'|) node of each P vertex
  std::vector<int32_t> b_node;   // (|V_B'|) node of each blade vertex
};

Nodes number_nodes(const Corefinement& core, const std::vector<int32_t>& patch_vertices, int32_t nv) {
  Nodes nodes;
  nodes.nv = nv;
  const std::size_t n_p = core.p_points.size();
  const std::size_t p_initial = patch_vertices.size();
  nodes.n_new_p = static_cast<int32_t>(n_p - p_initial);
  nodes.p_node.resize(n_p);
  std::unordered_map<PointKey, int32_t, PointKeyHash> node_at;
  node_at.reserve(n_p);
  // A new point that rounded onto an earlier one (of either mesh) is that node: the rounding merged them, and the
  // pieces between them, with a node twice, vanish in the repair (repair_rounding).
  for (std::size_t k = 0; k < n_p; ++k) {
    nodes.p_node[k] = k < p_initial ? patch_vertices[k] : nv + static_cast<int32_t>(k - p_initial);
    const auto [it, added] = node_at.emplace(PointKey(core.p_points[k]), nodes.p_node[k]);
    if (!added && k >= p_initial) nodes.p_node[k] = it->second;
  }
  nodes.b_node.resize(core.b_points.size());
  for (std::size_t v = 0; v < core.b_points.size(); ++v) {
    const auto [it, added] =
        node_at.emplace(PointKey(core.b_points[v]), nv + nodes.n_new_p + static_cast<int32_t>(v));
    nodes.b_node[v] = it->second;
  }
  return nodes;
}

// The kept pieces in node ids: P's pieces bucketed by the changing face they lie in, and the blade's.
struct Pieces {
  std::vector<int> bucket_begin;  // (|changing| + 1) the pieces of changing face i are p[bucket_begin[i]..[i + 1])
  std::vector<Tri> p;             // P's pieces, grouped by changing face, in CGAL's order within a face
  std::vector<Tri> b;             // the blade's pieces
};

Pieces bucket_pieces(const Corefinement& core, const Nodes& nodes, const std::vector<int32_t>& changing) {
  Pieces pieces;
  pieces.bucket_begin.assign(changing.size() + 1, 0);
  std::vector<std::vector<Tri>> by_face(changing.size());
  for (std::size_t i = 0; i < core.p_pieces.size(); ++i) {
    const Tri& t = core.p_pieces[i];
    const Tri n{nodes.p_node[static_cast<std::size_t>(t[0])], nodes.p_node[static_cast<std::size_t>(t[1])],
                nodes.p_node[static_cast<std::size_t>(t[2])]};
    const auto pos = std::lower_bound(changing.begin(), changing.end(), core.p_origin[i]) - changing.begin();
    by_face[static_cast<std::size_t>(pos)].push_back(n);
  }
  for (std::size_t i = 0; i < changing.size(); ++i) {
    pieces.bucket_begin[i + 1] = pieces.bucket_begin[i] + static_cast<int>(by_face[i].size());
    for (const Tri& t : by_face[i]) pieces.p.push_back(t);
  }
  pieces.b.reserve(core.b_pieces.size());
  for (const Tri& t : core.b_pieces) {
    pieces.b.push_back({nodes.b_node[static_cast<std::size_t>(t[0])], nodes.b_node[static_cast<std::size_t>(t[1])],
                        nodes.b_node[static_cast<std::size_t>(t[2])]});
  }
  return pieces;
}

// Phase 3a on the pieces (repair_rounding): flattened, repaired, and bucketed again (the pieces a collapse removed
// dropped, the order kept). A piece is whole when it is its face of S itself. Returns the number of collapses.
int repair_pieces(const sim::TriMesh& surface, FaceGrid& grid, const ChangingFaces& changing, const Corefinement& core,
                  const Nodes& nodes, std::size_t blade_input_vertices, double tiny_edge, Pieces& pieces) {
  PieceMesh mesh;
  mesh.surface = &surface;
  mesh.nv = nodes.nv;
  mesh.changing = &changing.faces;
  mesh.arcs = &changing.arcs;
  const auto n_new_p = static_cast<std::size_t>(nodes.n_new_p);
  const std::size_t p_initial = core.p_points.size() - n_new_p;
  for (std::size_t k = 0; k < n_new_p + core.b_points.size(); ++k) {
    mesh.new_points.push_back(k < n_new_p ? core.p_points[p_initial + k] : core.b_points[k - n_new_p]);
    mesh.constructed.push_back(k < n_new_p || k - n_new_p >= blade_input_vertices ? 1 : 0);
  }
  std::vector<int> owner;  // per piece: its changing face's position, or -1 for the blade's
  for (std::size_t i = 0; i + 1 < pieces.bucket_begin.size(); ++i) {
    const int n = pieces.bucket_begin[i + 1] - pieces.bucket_begin[i];
    for (int k = pieces.bucket_begin[i]; k < pieces.bucket_begin[i + 1]; ++k) {
      const Tri& t = pieces.p[static_cast<std::size_t>(k)];
      Tri old = surface.triangles[static_cast<std::size_t>(changing.faces[i])];
      bool same = false;
      for (int r = 0; r < 3 && n == 1; ++r) {
        same = same || (t[0] == old[r] && t[1] == old[(r + 1) % 3] && t[2] == old[(r + 2) % 3]);
      }
      mesh.tris.push_back(t);
      mesh.whole.push_back(same ? 1 : 0);
      mesh.blade.push_back(0);
      owner.push_back(static_cast<int>(i));
    }
  }
  for (const Tri& t : pieces.b) {
    mesh.tris.push_back(t);
    mesh.whole.push_back(0);
    mesh.blade.push_back(1);
    owner.push_back(-1);
  }
  mesh.alive.assign(mesh.tris.size(), 1);
  const int collapses = repair_rounding(mesh, grid, tiny_edge);
  if (collapses == 0) return 0;
  Pieces out;
  out.bucket_begin.assign(pieces.bucket_begin.size(), 0);
  for (std::size_t t = 0; t < mesh.tris.size(); ++t) {
    if (!mesh.alive[t]) continue;
    if (owner[t] < 0) {
      out.b.push_back(mesh.tris[t]);
    } else {
      out.p.push_back(mesh.tris[t]);
      ++out.bucket_begin[static_cast<std::size_t>(owner[t]) + 1];
    }
  }
  for (std::size_t i = 1; i < out.bucket_begin.size(); ++i) out.bucket_begin[i] += out.bucket_begin[i - 1];
  pieces = std::move(out);
  return collapses;
}

// Which new nodes a kept piece uses (|n_new_p| + |V_B'|, indexed by node - nv), and into `removed` (ascending) the
// old vertices of the changing faces that no kept piece uses and no face outside them does (those on their boundary,
// `changing.arcs`, always stay).
std::vector<char> used_new_nodes(const sim::TriMesh& surface, const ChangingFaces& changing, const Nodes& nodes,
                                 const Pieces& pieces, std::size_t b_vertices, std::vector<int32_t>& removed) {
  std::vector<int32_t> old_sorted(changing.patch_vertices);
  for (const int32_t f : changing.gone) {
    for (const int32_t v : surface.triangles[static_cast<std::size_t>(f)]) old_sorted.push_back(v);
  }
  std::sort(old_sorted.begin(), old_sorted.end());
  old_sorted.erase(std::unique(old_sorted.begin(), old_sorted.end()), old_sorted.end());
  std::vector<char> used_old(old_sorted.size(), 0);
  std::vector<char> used_new(static_cast<std::size_t>(nodes.n_new_p) + b_vertices, 0);
  const auto mark = [&](const Tri& t) {
    for (const int32_t n : t) {
      if (n < nodes.nv) {
        const auto it = std::lower_bound(old_sorted.begin(), old_sorted.end(), n);
        if (it != old_sorted.end() && *it == n) used_old[static_cast<std::size_t>(it - old_sorted.begin())] = 1;
      } else {
        used_new[static_cast<std::size_t>(n - nodes.nv)] = 1;
      }
    }
  };
  for (const Tri& t : pieces.p) mark(t);
  for (const Tri& t : pieces.b) mark(t);
  for (const auto& [v, arcs] : changing.arcs) {
    const auto it = std::lower_bound(old_sorted.begin(), old_sorted.end(), v);
    used_old[static_cast<std::size_t>(it - old_sorted.begin())] = 1;
  }
  for (std::size_t i = 0; i < old_sorted.size(); ++i) {
    if (!used_old[i]) removed.push_back(old_sorted[i]);
  }
  return used_new;
}

// The directed edges of the unchanged faces along the boundary of `old_tris` (the changing faces before the edit;
// vertex indices do not change in place): the reverses of their edges that no changing face has.
std::vector<std::array<int32_t, 2>> boundary_edges_of(const std::vector<Tri>& old_tris) {
  std::vector<uint64_t> directed;  // sorted
  directed.reserve(old_tris.size() * 3);
  const auto key = directed_edge_key;
  for (const Tri& t : old_tris) {
    for (int k = 0; k < 3; ++k) directed.push_back(key(t[k], t[(k + 1) % 3]));
  }
  std::sort(directed.begin(), directed.end());
  std::vector<std::array<int32_t, 2>> edges;
  for (const Tri& t : old_tris) {
    for (int k = 0; k < 3; ++k) {
      if (!std::binary_search(directed.begin(), directed.end(), key(t[(k + 1) % 3], t[k]))) {
        edges.push_back({t[(k + 1) % 3], t[k]});
      }
    }
  }
  return edges;
}

// Appends the new nodes a kept piece uses (`used_new`) to S; returns the vertex index of each (-1: unused) and sets
// written.constructed. A new P node is an intersection point; a blade node is one when it is not an input vertex of
// the blade (index >= blade_input_vertices).
std::vector<int32_t> add_new_vertices(SurfaceEditor& editor, const Corefinement& core, const Nodes& nodes,
                                      const std::vector<char>& used_new, std::size_t blade_input_vertices,
                                      WrittenPatch& written) {
  const auto n_new_p = static_cast<std::size_t>(nodes.n_new_p);
  const std::size_t p_initial = core.p_points.size() - n_new_p;
  std::vector<int32_t> new_to_out(used_new.size(), -1);
  for (std::size_t k = 0; k < used_new.size(); ++k) {
    if (!used_new[k]) continue;
    written.constructed.push_back(k < n_new_p || k - n_new_p >= blade_input_vertices ? 1 : 0);
    const Vec3& p = k < n_new_p ? core.p_points[p_initial + k] : core.b_points[k - n_new_p];
    new_to_out[k] = editor.add_vertex(p);
  }
  return new_to_out;
}

}  // namespace

WrittenPatch write_back(SurfaceEditor& editor, const ChangingFaces& changing, const Corefinement& core,
                        std::size_t blade_input_vertices, const Vec3& centre, bool boundary_edges, bool repair,
                        double tiny_edge, SurfaceEditResult& result) {
  const sim::TriMesh& surface = editor.mesh();
  const std::vector<int32_t>& faces = changing.faces;
  const Nodes nodes = number_nodes(core, changing.patch_vertices, static_cast<int32_t>(surface.vertices.size()));
  Pieces pieces = bucket_pieces(core, nodes, faces);
  if (repair) {
    result.collapses = repair_pieces(surface, editor.grid(), changing, core, nodes, blade_input_vertices, tiny_edge,
                                     pieces);
  }
  result.blade_triangles_kept = static_cast<int>(pieces.b.size());
  const std::vector<char> used_new =
      used_new_nodes(surface, changing, nodes, pieces, core.b_points.size(), result.removed_vertices);

  // The old triangles of the changing faces, their attributes and their share of the volume, read before anything
  // is written. A face kept whole (one piece with its own vertices) is unchanged and counts in neither volume.
  std::vector<Tri> old_tris(faces.size());
  std::vector<FaceAttributes> old_attributes(faces.size());
  std::vector<char> whole(faces.size(), 0);
  double volume_before = 0.0, volume_after = 0.0;  // m^3, over the changed faces, relative to `centre`
  for (std::size_t i = 0; i < faces.size(); ++i) {
    old_tris[i] = surface.triangles[static_cast<std::size_t>(faces[i])];
    old_attributes[i] = editor.attributes(faces[i]);
    if (pieces.bucket_begin[i + 1] - pieces.bucket_begin[i] == 1) {
      const Tri& only = pieces.p[static_cast<std::size_t>(pieces.bucket_begin[i])];
      const Tri& old = old_tris[i];
      for (int r = 0; r < 3; ++r) {
        whole[i] = whole[i] || (only[0] == old[r] && only[1] == old[(r + 1) % 3] && only[2] == old[(r + 2) % 3]);
      }
    }
    if (!whole[i]) volume_before += tet_volume(centre, surface, old_tris[i]);
  }
  WrittenPatch written;
  written.intersections_checked = repair;
  if (boundary_edges) written.boundary_edges = boundary_edges_of(old_tris);

  // From here on S is edited in place (the caller rolls the edits back when a later step throws). New vertices are
  // appended: the new P vertices, then the new blade vertices.
  const std::vector<int32_t> new_to_out =
      add_new_vertices(editor, core, nodes, used_new, blade_input_vertices, written);
  const sim::TriMesh& out = editor.mesh();
  const auto out_index = [&](int32_t n) {
    return n < nodes.nv ? n : new_to_out[static_cast<std::size_t>(n - nodes.nv)];
  };

  // The new triangles: each changing face's kept pieces (which inherit its attributes), then the blade's. They fill
  // the changing faces' slots in order; the rest are appended, or the slots left over are removed (the last
  // triangles move into them).
  std::size_t slot = 0;
  const auto place = [&](const Tri& n, FaceAttributes a, char kept_whole) {
    const Tri o{out_index(n[0]), out_index(n[1]), out_index(n[2])};
    int32_t f = 0;
    if (slot < faces.size()) {
      f = faces[slot++];
      editor.set_face(f, o, a);
    } else {
      f = editor.add_face(o, a);
    }
    written.changed.push_back(f);
    written.changed_whole.push_back(kept_whole);
    if (!kept_whole) volume_after += tet_volume(centre, out, o);
  };
  for (std::size_t i = 0; i < faces.size(); ++i) {
    for (int k = pieces.bucket_begin[i]; k < pieces.bucket_begin[i + 1]; ++k) {
      place(pieces.p[static_cast<std::size_t>(k)], old_attributes[i], whole[i]);
    }
  }
  for (const Tri& n : pieces.b) place(n, FaceAttributes{1, -1}, 0);
  editor.remove_faces(std::span<const int32_t>(faces).subspan(slot));
  result.removed_volume = volume_before - volume_after;
  return written;
}

}  // namespace octocut::cutting::surface_cut_detail
