#pragma once
// Topology of a triangle surface (SPEC §2.4): closedness, edge and vertex manifoldness, consistent orientation and
// connected components. Purely combinatorial: positions are never read. The mesh loader, the report and the cutting
// pipeline share it to state `surface.closed` and `surface.components`.
#include <array>
#include <cstdint>

#include "octocut/sim/surface.hpp"

namespace octocut::sim {

/// An undirected edge (lo < hi) and one triangle that uses it; lo = hi = tri = -1 when there is none.
struct EdgeOffender {
  std::array<int32_t, 2> edge{-1, -1}; ///< vertex indices, lo < hi
  int32_t triangle = -1;               ///< the first triangle (lowest index) that uses the edge
  int32_t other_triangle = -1;         ///< a second triangle that uses the edge, or -1
  int32_t uses = 0;                    ///< how many triangles use the edge
  [[nodiscard]] bool found() const { return triangle >= 0; }
};

/// The topology of a triangle mesh. Each "first offender" is the lowest (lo, hi) edge or the lowest vertex index with
/// the defect, so that the report is deterministic. Triangles with a repeated vertex index contribute no edges.
struct SurfaceCheck {
  bool closed = true;          ///< every undirected edge is used by exactly 2 triangles
  bool edge_manifold = true;   ///< no edge is used by more than 2 triangles
  bool vertex_manifold = true; ///< the triangles around every used vertex form one fan (one edge-connected ring/arc)
  bool oriented = true;        ///< every edge used by 2 triangles is used once in each direction
  int components = 0;          ///< connected components of triangles (linked through shared vertices)
  EdgeOffender boundary_edge;     ///< first edge used by exactly 1 triangle (the mesh has a hole)
  EdgeOffender nonmanifold_edge;  ///< first edge used by more than 2 triangles
  EdgeOffender misoriented_edge;  ///< first edge used twice in the same direction
  int32_t nonmanifold_vertex = -1; ///< first vertex whose triangles form more than one fan, or -1
  int32_t nonmanifold_vertex_fans = 0; ///< how many separate fans meet at nonmanifold_vertex
};

/// Checks the topology of `mesh` in O(|F| log |F|). Throws std::invalid_argument naming the triangle when a vertex
/// index is negative or not below |V|.
SurfaceCheck check_surface(const TriMesh& mesh);

}  // namespace octocut::sim
