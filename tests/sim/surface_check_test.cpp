// Tests for sim::check_surface, the topology check of a triangle surface: closedness, edge and vertex manifoldness,
// orientation and components, each against a hand-built mesh whose defect is known.
#include "octocut/sim/surface_check.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <stdexcept>
#include <vector>

#include "cutting/test_meshes.hpp"

namespace octocut::sim {
namespace {

using test::grid_cube;
using test::octahedron;

TEST(SurfaceCheck, ClosedMeshesAndComponents) {
  const sim::SurfaceCheck one = sim::check_surface(grid_cube(3));
  EXPECT_TRUE(one.closed && one.edge_manifold && one.vertex_manifold && one.oriented);
  EXPECT_EQ(one.components, 1);

  const sim::SurfaceCheck two = sim::check_surface(test::merged(grid_cube(2), grid_cube(1, 1.0, sim::Vec3(3, 0, 0))));
  EXPECT_TRUE(two.closed && two.edge_manifold && two.vertex_manifold && two.oriented);
  EXPECT_EQ(two.components, 2);
}

TEST(SurfaceCheck, OpenEdgeAndMisorientedEdgeAreFound) {
  sim::TriMesh mesh = octahedron();
  const auto removed = mesh.triangles.back();
  mesh.triangles.pop_back();
  const sim::SurfaceCheck open = sim::check_surface(mesh);
  EXPECT_FALSE(open.closed);
  ASSERT_TRUE(open.boundary_edge.found());
  // The lowest boundary edge is the lowest edge of the removed triangle.
  std::vector<std::array<int32_t, 2>> edges;
  for (int k = 0; k < 3; ++k) {
    const int32_t a = removed[k], b = removed[(k + 1) % 3];
    edges.push_back({std::min(a, b), std::max(a, b)});
  }
  EXPECT_EQ(open.boundary_edge.edge, *std::min_element(edges.begin(), edges.end()));
  EXPECT_EQ(open.boundary_edge.uses, 1);

  mesh = octahedron();
  std::swap(mesh.triangles[2][0], mesh.triangles[2][1]);
  const sim::SurfaceCheck flipped = sim::check_surface(mesh);
  EXPECT_TRUE(flipped.closed);
  EXPECT_FALSE(flipped.oriented);
  EXPECT_TRUE(flipped.misoriented_edge.triangle == 2 || flipped.misoriented_edge.other_triangle == 2);
}

TEST(SurfaceCheck, TwoTetrahedraSharingOneVertexAreNotVertexManifold) {
  // Vertex 0 is the apex of both: each edge is used twice, but the triangles around vertex 0 form two fans.
  sim::TriMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}, {0, 4, 5}, {0, 6, 4}, {0, 5, 6}, {4, 6, 5}};
  const sim::SurfaceCheck check = sim::check_surface(mesh);
  EXPECT_TRUE(check.closed);
  EXPECT_TRUE(check.edge_manifold);
  EXPECT_FALSE(check.vertex_manifold);
  EXPECT_EQ(check.nonmanifold_vertex, 0);
  EXPECT_EQ(check.nonmanifold_vertex_fans, 2);
  EXPECT_EQ(check.components, 1);
}

TEST(SurfaceCheck, OutOfRangeIndexThrows) {
  sim::TriMesh mesh = octahedron();
  mesh.triangles[1][2] = -1;
  EXPECT_THROW((void)sim::check_surface(mesh), std::invalid_argument);
}

}  // namespace
}  // namespace octocut::sim
