#pragma once
// An independent watertightness check for cut surfaces (own edge and fan counting, CGAL's exact self-intersection
// test), shared by the surface-boolean and pipeline tests.
#include <gtest/gtest.h>

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "octocut/cutting/mesh_check.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::test {

// Independent watertightness check: every directed edge once and its reverse once, one fan per vertex, no unused
// vertex, no degenerate triangle, no self-intersection.
inline void expect_watertight(const sim::TriMesh& m, const std::string& what) {
  std::map<std::pair<int32_t, int32_t>, int> directed;
  for (const auto& t : m.triangles) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_GE(t[k], 0) << what;
      ASSERT_LT(t[k], static_cast<int32_t>(m.vertices.size())) << what;
      ++directed[{t[k], t[(k + 1) % 3]}];
    }
    const sim::Vec3& a = m.vertices[static_cast<std::size_t>(t[0])];
    const sim::Vec3& b = m.vertices[static_cast<std::size_t>(t[1])];
    const sim::Vec3& c = m.vertices[static_cast<std::size_t>(t[2])];
    ASSERT_GT((b - a).cross(c - a).norm(), 0.0) << what << ": degenerate triangle";
  }
  for (const auto& [e, n] : directed) {
    ASSERT_EQ(n, 1) << what << ": edge " << e.first << "-" << e.second << " used twice in one direction";
    const auto it = directed.find({e.second, e.first});
    ASSERT_TRUE(it != directed.end()) << what << ": boundary edge " << e.first << "-" << e.second;
  }
  // One fan per vertex: walk around each vertex by next-edge links.
  std::vector<std::vector<std::pair<int32_t, int32_t>>> around(m.vertices.size());  // (out, in) per corner
  for (const auto& t : m.triangles) {
    for (int k = 0; k < 3; ++k) around[static_cast<std::size_t>(t[k])].emplace_back(t[(k + 1) % 3], t[(k + 2) % 3]);
  }
  for (std::size_t v = 0; v < around.size(); ++v) {
    const auto& c = around[v];
    ASSERT_FALSE(c.empty()) << what << ": vertex " << v << " is unused";
    std::map<int32_t, int32_t> next;  // out -> in of the same corner, i.e. the fan continues at corner with out == in
    for (const auto& [o, i] : c) next[o] = i;
    std::size_t steps = 0;
    int32_t at = c[0].first;
    do {
      at = next.at(at);
      ++steps;
    } while (at != c[0].first && steps <= c.size());
    ASSERT_EQ(steps, c.size()) << what << ": vertex " << v << " is not manifold";
  }
  const auto hit = cutting::find_self_intersection(m);
  ASSERT_FALSE(hit.has_value()) << what << ": triangles " << (*hit)[0] << " and " << (*hit)[1] << " intersect";
}

}  // namespace octocut::test
