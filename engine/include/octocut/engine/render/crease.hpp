#pragma once
// Normals that do not smear across creases. Averaging vertex normals across the crease between a cut wall and the
// surface it goes through draws dark and light streaks around every hole. The tissue is therefore drawn with its
// vertices split into smooth patches: around each vertex of S, faces that meet across an edge share a normal only when
// both are cut faces or both are not, and their rest-space normals differ by at most the crease angle. GL-free.
#include <array>
#include <cstdint>
#include <vector>

#include "octocut/engine/render/render_scene.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::engine {

/// S's triangles over split vertices: one render vertex per smooth patch around each vertex of S.
struct CreaseTopology {
  std::vector<std::int32_t> vertex_of;                 ///< per render vertex, its vertex of S (|V'| >= |V|)
  std::vector<std::array<std::int32_t, 3>> triangles;  ///< S's triangles, in S's order, over render vertices (|F|)
};

/// Groups the corners of `rest`'s triangles into smooth patches (see above). `cut_faces` marks the triangles that
/// came from a blade (|F|, 1 = cut; empty: none). `crease_angle_deg` in [0, 180]: edges whose faces' normals differ
/// by more are creases; 180 splits only at cut/uncut boundaries and at edges not shared by exactly two faces.
/// Degenerate (zero-area) triangles join their neighbours. O(|F| times the vertex degree); deterministic.
CreaseTopology crease_topology(const sim::TriMesh& rest, const std::vector<char>& cut_faces, double crease_angle_deg);

/// The tissue mesh drawn from `topology` with S's deformed positions (|V|, m): positions per render vertex, unit
/// normals that are the area-weighted mean of each patch's deformed face normals, cut faces marked from `cut_faces`.
RenderMesh crease_mesh(const CreaseTopology& topology, const std::vector<sim::Vec3>& deformed,
                       const std::vector<char>& cut_faces);

}  // namespace octocut::engine
