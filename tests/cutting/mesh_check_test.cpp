// Tests for the CGAL self-intersection query, against brute-force triangle intersection as independent truth.
#include "octocut/cutting/mesh_check.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <stdexcept>

#include "test_meshes.hpp"

namespace octocut::cutting {
namespace {

using test::grid_cube;
using test::merged;

TEST(MeshCheck, ClosedConvexMeshesDoNotSelfIntersect) {
  // Neighbouring triangles share vertices and edges; that is not an intersection.
  EXPECT_FALSE(find_self_intersection(test::octahedron()).has_value());
  EXPECT_FALSE(find_self_intersection(grid_cube(4)).has_value());
}

TEST(MeshCheck, TriangleOrderDoesNotMatter) {
  // Surface_mesh is built face by face; a shuffled order must neither fail nor change the answer.
  std::mt19937 random(11);
  sim::TriMesh sphere = test::cube_sphere(8);
  std::shuffle(sphere.triangles.begin(), sphere.triangles.end(), random);
  EXPECT_FALSE(find_self_intersection(sphere).has_value());

  // For two interpenetrating boxes, reversing the triangle order maps the smallest pair {f, g} of the reversed mesh
  // back to a pair of the original that brute force confirms.
  const sim::TriMesh two = merged(grid_cube(2), grid_cube(2, 1.0, sim::Vec3(0.5, 0.37, 0.21)));
  sim::TriMesh reversed = two;
  std::reverse(reversed.triangles.begin(), reversed.triangles.end());
  const auto pair = find_self_intersection(reversed);
  ASSERT_TRUE(pair.has_value());
  const auto last = static_cast<int>(two.num_triangles()) - 1;
  EXPECT_TRUE(test::triangles_intersect(two, static_cast<std::size_t>(last - (*pair)[0]),
                                        static_cast<std::size_t>(last - (*pair)[1])));
}

TEST(MeshCheck, DisjointBoxesDoNotIntersect) {
  const sim::TriMesh two = merged(grid_cube(2), grid_cube(2, 1.0, sim::Vec3(1.5, 0.2, 0.1)));
  EXPECT_FALSE(find_self_intersection(two).has_value());
}

TEST(MeshCheck, InterpenetratingBoxesReportTheSmallestIntersectingPair) {
  // Two unit boxes, the second shifted by a generic offset so that no faces are coplanar or merely touching.
  const sim::TriMesh a = grid_cube(1);
  const sim::TriMesh two = merged(a, grid_cube(1, 1.0, sim::Vec3(0.5, 0.37, 0.21)));
  const auto pair = find_self_intersection(two);
  ASSERT_TRUE(pair.has_value());
  const auto [f, g] = *pair;
  const auto first_box = static_cast<int>(a.num_triangles());

  // The pair is one triangle of each box, and brute force agrees that they intersect.
  EXPECT_LT(f, first_box);
  EXPECT_GE(g, first_box);
  EXPECT_TRUE(test::triangles_intersect(two, static_cast<std::size_t>(f), static_cast<std::size_t>(g)));

  // No lexicographically smaller pair across the two boxes intersects (within a box they share vertices or are
  // disjoint faces of a convex box).
  for (int i = 0; i <= f; ++i) {
    for (int j = first_box; j < static_cast<int>(two.num_triangles()); ++j) {
      if (i == f && j >= g) break;
      EXPECT_FALSE(test::triangles_intersect(two, static_cast<std::size_t>(i), static_cast<std::size_t>(j)))
          << "triangles " << i << " and " << j << " intersect but " << f << ", " << g << " was reported";
    }
  }
}

TEST(MeshCheck, SelfIntersectionIsFoundInsideOneComponent) {
  // Push one vertex of a sphere through the opposite side: its fan now pierces the far cap.
  sim::TriMesh sphere = test::cube_sphere(4);
  std::size_t top = 0;
  for (std::size_t v = 0; v < sphere.num_vertices(); ++v) {
    if (sphere.vertices[v].z() > sphere.vertices[top].z()) top = v;
  }
  sphere.vertices[top] = sim::Vec3(0.013, 0.021, -1.6);
  const auto pair = find_self_intersection(sphere);
  ASSERT_TRUE(pair.has_value());
  EXPECT_TRUE(test::triangles_intersect(sphere, static_cast<std::size_t>((*pair)[0]),
                                        static_cast<std::size_t>((*pair)[1])));
}

TEST(MeshCheck, DegenerateOrBrokenInputIsRejectedWithTheTriangle) {
  sim::TriMesh mesh = test::octahedron();
  mesh.triangles[3] = {mesh.triangles[3][0], mesh.triangles[3][0], mesh.triangles[3][1]};
  try {
    (void)find_self_intersection(mesh);
    FAIL() << "no error for a degenerate triangle";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("triangle 3"), std::string::npos) << error.what();
  }
  mesh = test::octahedron();
  mesh.triangles[5][1] = 6;
  EXPECT_THROW((void)find_self_intersection(mesh), std::invalid_argument);
}

TEST(MeshCheck, FiftyThousandVertexSphereIsCleanAndTimed) {
  // 6 * 91^2 + 2 = 49688 vertices, 99372 triangles.
  const sim::TriMesh sphere = test::cube_sphere(91);
  ASSERT_EQ(sphere.num_vertices(), 49688u);
  const auto start = std::chrono::steady_clock::now();
  const auto pair = find_self_intersection(sphere);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  EXPECT_FALSE(pair.has_value());
  std::printf("find_self_intersection: %zu vertices, %zu triangles: %.1f ms\n", sphere.num_vertices(),
              sphere.num_triangles(), ms);
  ::testing::Test::RecordProperty("self_intersection_ms", std::to_string(ms));
}

}  // namespace
}  // namespace octocut::cutting
