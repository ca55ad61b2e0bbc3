// The surface embedding (SPEC §2.4): construction, the vertex-to-triangle adjacency, and the per-step deformed
// positions and normals. The Z-curve list is in zcurve.cpp, the binding of vertices to leaves (with the fallback
// rule) in embed_vertex.cpp, the composition through P in embedding_compose.cpp, the update after a cut in
// embedding_update.cpp.
#include "octocut/sim/embedding.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "embedding_internal.hpp"

namespace octocut::sim {

namespace detail {

std::string describe_point(const char* what, std::size_t i, const Vec3& p) {
  return std::string(what) + " " + std::to_string(i) + " (" + std::to_string(p.x()) + ", " + std::to_string(p.y()) +
         ", " + std::to_string(p.z()) + ")";
}

void check_index_list(std::span<const int> list, std::size_t n, const char* what) {
  std::vector<char> seen(n, 0);
  for (std::size_t i = 0; i < list.size(); ++i) {
    const int v = list[i];
    if (v < 0 || std::size_t(v) >= n)
      throw std::invalid_argument(std::string(what) + "[" + std::to_string(i) + "] = " + std::to_string(v) +
                                  " is out of range [0, " + std::to_string(n) + ")");
    if (seen[std::size_t(v)])
      throw std::invalid_argument(std::string(what) + "[" + std::to_string(i) + "] = " + std::to_string(v) +
                                  " is listed twice");
    seen[std::size_t(v)] = 1;
  }
}

void check_finite(std::span<const Vec3> points, const char* what) {
  for (std::size_t i = 0; i < points.size(); ++i)
    if (!points[i].allFinite()) throw std::invalid_argument(describe_point(what, i, points[i]) + " is not finite");
}

}  // namespace detail

SurfaceEmbedding::SurfaceEmbedding(const ObjectModel& model, const TriMesh& surface)
    : m_root(model.root()), m_tree(model.tree()) {
  const std::size_t nv = surface.vertices.size();
  count_corners(surface.triangles, nv);
  m_zcurve = ZCurveList(m_root, surface.vertices);
  m_embedding.assign(nv, VertexEmbedding{});
  build_adjacency(surface.triangles, nv);
  embed(model, surface, {}, true);
  compose(model.dofs(), {}, {});
  m_last_reembedded = num_vertices();
  // Room for the first cuts, written once here, so that the first update() neither moves the per-vertex arrays
  // and the CSR nor takes its scratch pages from the system (a cut adds a few hundred vertices at most).
  const std::size_t room = nv + nv / 8;
  m_embedding.reserve(room);
  m_dof.reserve(m_dof.size() + m_dof.size() / 8);
  m_weight.reserve(m_dof.capacity());
  m_next_begin.assign(room + 1, 0);
  m_next_tri_begin.assign(room + 2, 0);
  m_redo.assign(room, 0);
  m_reuse_from.assign(room, 0);
}

bool SurfaceEmbedding::matches(const TriMesh& surface) const {
  return surface.vertices.size() == m_embedding.size() && 3 * surface.triangles.size() == m_tri.size();
}

void SurfaceEmbedding::check_matches(const TriMesh& surface, const char* who) const {
  if (!matches(surface))
    throw std::invalid_argument(std::string(who) + ": the surface has " + std::to_string(surface.vertices.size()) +
                                " vertices and " + std::to_string(surface.triangles.size()) +
                                " triangles; the embedding is built for " + std::to_string(num_vertices()) +
                                " and " + std::to_string(num_triangles()));
}

std::span<const ZEntry> SurfaceEmbedding::vertices_in_leaf(int leaf) const {
  if (leaf < 0 || leaf >= m_tree.size())
    throw std::out_of_range("SurfaceEmbedding::vertices_in_leaf: leaf " + std::to_string(leaf) + " out of range");
  return m_zcurve.in_cell(m_tree.leaf(leaf));
}

int SurfaceEmbedding::num_fallback() const {
  return int(std::count_if(m_embedding.begin(), m_embedding.end(), [](const auto& e) { return e.fallback; }));
}

void SurfaceEmbedding::check_triangles(const std::vector<std::array<int32_t, 3>>& triangles,
                                       std::size_t num_vertices) {
  // One unsigned comparison per corner (negative indices wrap above any size); the search for the culprit only on
  // failure.
  std::uint32_t largest = 0;
  for (const auto& t : triangles)
    largest = std::max({largest, std::uint32_t(t[0]), std::uint32_t(t[1]), std::uint32_t(t[2])});
  if (triangles.empty() || std::size_t(largest) < num_vertices) return;
  for (std::size_t t = 0; t < triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int32_t v = triangles[t][std::size_t(k)];
      if (v < 0 || std::size_t(v) >= num_vertices)
        throw std::invalid_argument("triangle " + std::to_string(t) + " corner " + std::to_string(k) + " = " +
                                    std::to_string(v) + " is out of range [0, " + std::to_string(num_vertices) + ")");
    }
}

void SurfaceEmbedding::count_corners(const std::vector<std::array<int32_t, 3>>& triangles, std::size_t num_vertices) {
  // The corners at vertex v are counted at [v + 2], so that build_adjacency() turns the counts into row starts in
  // place. One unsigned comparison per corner (negative indices wrap above any size); the culprit is searched for
  // only on failure.
  std::vector<int>& count = m_next_tri_begin;
  count.assign(num_vertices + 2, 0);
  bool bad = false;
  for (const auto& t : triangles)
    for (const int32_t v : t) {
      if (std::size_t(std::uint32_t(v)) < num_vertices)
        ++count[std::size_t(v) + 2];
      else
        bad = true;
    }
  if (bad) check_triangles(triangles, num_vertices);
}

void SurfaceEmbedding::build_adjacency(const std::vector<std::array<int32_t, 3>>& triangles, std::size_t nv) {
  // Vertex-to-triangle CSR; a triangle appears once per corner it has at the vertex, triangles ascending. A counting
  // sort on the counts of count_corners(): after the prefix sum, start[v + 1] is the first slot of vertex v; the
  // scatter advances it to the first slot of v + 1, so that start[0 .. |V|] ends up as the row starts.
  std::vector<int>& start = m_next_tri_begin;
  for (std::size_t i = 2; i < nv + 2; ++i) start[i] += start[i - 1];
  m_tri.resize(std::size_t(start[nv + 1]));
  int* slot = start.data() + 1;
  int* tri = m_tri.data();
  for (std::size_t t = 0; t < triangles.size(); ++t)
    for (const int32_t v : triangles[t]) tri[slot[v]++] = int(t);
  start.pop_back();
  m_tri_begin.swap(start);
}

void SurfaceEmbedding::deformed_positions(const std::vector<Vec3>& x_dofs, std::vector<Vec3>& positions,
                                          Executor& exec) const {
  if (int(x_dofs.size()) != m_num_dofs)
    throw std::invalid_argument("SurfaceEmbedding::deformed_positions: " + std::to_string(x_dofs.size()) +
                                " DOF positions for a model with " + std::to_string(m_num_dofs) + " DOFs");
  positions.resize(m_embedding.size());
  // Each vertex is written by exactly one task: the result does not depend on the thread count.
  exec.parallel_for(num_vertices(), 2048, [&](int begin, int end) {
    for (int v = begin; v < end; ++v) {
      Vec3 p = Vec3::Zero();
      for (int i = m_begin[std::size_t(v)]; i < m_begin[std::size_t(v) + 1]; ++i)
        p += m_weight[std::size_t(i)] * x_dofs[std::size_t(m_dof[std::size_t(i)])];
      positions[std::size_t(v)] = p;
    }
  });
}

void SurfaceEmbedding::deformed_normals(const TriMesh& surface, const std::vector<Vec3>& positions,
                                        std::vector<Vec3>& normals, Executor& exec) const {
  std::vector<Vec3> face_normals;
  deformed_normals(surface, positions, normals, exec, face_normals);
}

void SurfaceEmbedding::deformed_normals(const TriMesh& surface, const std::vector<Vec3>& positions,
                                        std::vector<Vec3>& normals, Executor& exec,
                                        std::vector<Vec3>& face_normals) const {
  check_matches(surface, "SurfaceEmbedding::deformed_normals");
  if (positions.size() != m_embedding.size())
    throw std::invalid_argument("SurfaceEmbedding::deformed_normals: " + std::to_string(positions.size()) +
                                " positions for " + std::to_string(m_embedding.size()) + " vertices");
  const std::vector<std::array<int32_t, 3>>& triangles = surface.triangles;
  // Face normals (twice the area times the unit normal), one task per triangle range.
  face_normals.resize(triangles.size());
  exec.parallel_for(int(triangles.size()), 4096, [&](int begin, int end) {
    for (int t = begin; t < end; ++t) {
      const auto& tri = triangles[std::size_t(t)];
      const Vec3& a = positions[std::size_t(tri[0])];
      face_normals[std::size_t(t)] = (positions[std::size_t(tri[1])] - a).cross(positions[std::size_t(tri[2])] - a);
    }
  });
  // Each vertex sums its incident faces in triangle order, as sim::vertex_normals does, and normalises.
  normals.resize(m_embedding.size());
  exec.parallel_for(num_vertices(), 2048, [&](int begin, int end) {
    for (int v = begin; v < end; ++v) {
      Vec3 n = Vec3::Zero();
      for (int i = m_tri_begin[std::size_t(v)]; i < m_tri_begin[std::size_t(v) + 1]; ++i)
        n += face_normals[std::size_t(m_tri[std::size_t(i)])];
      const double len = n.norm();
      normals[std::size_t(v)] = len > 0.0 ? Vec3(n / len) : Vec3::Zero();
    }
  });
}

}  // namespace octocut::sim
