#pragma once
// A closed triangle surface S in rest space (SPEC §2.4): the plain mesh data that the loaders, the procedural
// generators, the material graph, the embedding and the renderer share. No third-party types.
#include <array>
#include <cstdint>
#include <vector>

#include "octocut/sim/types.hpp"

namespace octocut::sim {

/// An indexed triangle mesh. Triangles are counter-clockwise seen from outside, so that normals point out.
struct TriMesh {
  std::vector<Vec3> vertices;                    ///< positions, m (|V|)
  std::vector<std::array<int32_t, 3>> triangles; ///< vertex indices (|F|)

  [[nodiscard]] std::size_t num_vertices() const { return vertices.size(); }
  [[nodiscard]] std::size_t num_triangles() const { return triangles.size(); }
};

/// Signed volume enclosed by the mesh (divergence theorem), m^3: positive for an outward-oriented closed mesh.
double signed_volume(const TriMesh& mesh);

/// Axis-aligned bounding box of the vertices, m. A zero box for an empty mesh.
Box3 bounds(const TriMesh& mesh);

/// Area-weighted vertex normals, unit length (|V|); zero for a vertex that no non-degenerate triangle uses.
std::vector<Vec3> vertex_normals(const std::vector<Vec3>& positions,
                                 const std::vector<std::array<int32_t, 3>>& triangles);

}  // namespace octocut::sim
