// Octree addressing, Morton order, point location and state-preserving refinement (SPEC §2.1).
#include <gtest/gtest.h>

#include <random>

#include "octocut/sim/octree.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

TEST(Morton, InterleavesBitsXLowest) {
  EXPECT_EQ(morton_encode(1, 0, 0), 1u);
  EXPECT_EQ(morton_encode(0, 1, 0), 2u);
  EXPECT_EQ(morton_encode(0, 0, 1), 4u);
  EXPECT_EQ(morton_encode(3, 0, 0), 0b1001u);
  // Top bit of each 21-bit coordinate lands at bits 60, 61, 62.
  EXPECT_EQ(morton_encode(1u << 20, 1u << 20, 1u << 20), 7ull << 60);
  // Brute-force interleave on random coordinates.
  std::mt19937 rng(1);
  for (int i = 0; i < 1000; ++i) {
    const std::uint32_t x = rng() & 0x1FFFFF, y = rng() & 0x1FFFFF, z = rng() & 0x1FFFFF;
    std::uint64_t ref = 0;
    for (int b = 0; b < 21; ++b) {
      ref |= std::uint64_t((x >> b) & 1) << (3 * b);
      ref |= std::uint64_t((y >> b) & 1) << (3 * b + 1);
      ref |= std::uint64_t((z >> b) & 1) << (3 * b + 2);
    }
    ASSERT_EQ(morton_encode(x, y, z), ref);
  }
}

// An adaptive tree: root refined to level 2, then a few cells refined down to level 6 at a corner.
Octree adaptive_tree() {
  std::vector<Cell> cells;
  std::vector<Cell> stack{Cell{}};
  while (!stack.empty()) {
    Cell c = stack.back();
    stack.pop_back();
    const bool at_origin = c.anchor.x == 0 && c.anchor.y == 0;
    if (c.level < 2 || (at_origin && c.level < 6)) {
      for (int k = 0; k < 8; ++k) stack.push_back(c.child(k));
    } else {
      cells.push_back(c);
    }
  }
  return Octree(cells);
}

TEST(Octree, LeavesAreInMortonOrderAndLocateAgreesWithBruteForce) {
  const Octree tree = adaptive_tree();
  for (int i = 1; i < tree.size(); ++i) ASSERT_LT(tree.leaf(i - 1).morton(), tree.leaf(i).morton());
  std::mt19937 rng(7);
  for (int i = 0; i < 5000; ++i) {
    const GridPoint p{std::uint32_t(rng() % kGridCells), std::uint32_t(rng() % kGridCells),
                      std::uint32_t(rng() % kGridCells)};
    int brute = -1;
    for (int l = 0; l < tree.size(); ++l)
      if (tree.leaf(l).contains_cell(p)) brute = l;
    ASSERT_EQ(tree.locate_cell(p), brute);
    ASSERT_GE(brute, 0);  // the tree covers the root completely
  }
}

TEST(Octree, LocateMissesDroppedLeaves) {
  Octree full = adaptive_tree();
  std::vector<Cell> cells = full.leaves();
  const Cell dropped = cells[3];
  cells.erase(cells.begin() + 3);
  const Octree tree(cells);
  EXPECT_EQ(tree.locate_cell(dropped.anchor), -1);
  EXPECT_EQ(tree.find(dropped), -1);
  EXPECT_EQ(tree.find(cells[3]), 3);
}

TEST(Octree, UnrestrictedNeighboursDifferByManyLevels) {
  const Octree tree = adaptive_tree();
  // The level-6 cell at the origin's +x side touches level-2 cells: a jump of 4 levels is kept, no 2:1 balancing.
  int max_level = 0, min_level = 99;
  for (const Cell& c : tree.leaves()) {
    max_level = std::max(max_level, c.level);
    min_level = std::min(min_level, c.level);
  }
  EXPECT_EQ(max_level, 6);
  EXPECT_EQ(min_level, 2);
}

TEST(Octree, RefinePreservesDeformedPositionAndVelocity) {
  const Box3 box{Vec3(0, 0, 0), Vec3(1, 1, 1)};
  ObjectModel m = test::box_model(box, Vec3(0, 0, 0), 1.0, 2);
  // A smooth nonlinear deformation and velocity field on the DOFs.
  SimState s = SimState::rest(m);
  for (std::size_t d = 0; d < s.x.size(); ++d) {
    const Vec3 X = s.x[d];
    s.x[d] = X + Vec3(0.1 * std::sin(3 * X.y()), 0.05 * X.x() * X.z(), 0.2 * X.x() * X.x());
    s.v[d] = Vec3(X.z(), -X.x() * X.y(), 1.0);
  }
  std::vector<Vec3> xs, vs;
  m.dofs().prolong(s.x, xs);
  m.dofs().prolong(s.v, vs);

  // Refine two leaves, then one child again: hanging nodes with chains appear.
  ObjectModel r1 = m.refined({0, 5});
  SimState s1 = transfer_state(m, s, r1);
  ObjectModel r2 = r1.refined({1});
  SimState s2 = transfer_state(r1, s1, r2);
  ASSERT_EQ(r2.dofs().check_invariants(), "");
  EXPECT_GT(r2.dofs().hanging_slots, 0);
  std::vector<Vec3> xs2, vs2;
  r2.dofs().prolong(s2.x, xs2);
  r2.dofs().prolong(s2.v, vs2);

  // Every rest point interpolates to the same deformed position and velocity before and after.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int i = 0; i < 2000; ++i) {
    const Vec3 X(u(rng), u(rng), u(rng));
    const auto e0 = m.embed(X);
    const auto e2 = r2.embed(X);
    ASSERT_TRUE(e0 && e2);
    EXPECT_LT((m.evaluate(*e0, xs) - r2.evaluate(*e2, xs2)).norm(), 1e-12);
    EXPECT_LT((m.evaluate(*e0, vs) - r2.evaluate(*e2, vs2)).norm(), 1e-12);
  }
}

TEST(Octree, EmbeddingReproducesRestPositions) {
  const Box3 box{Vec3(0.01, 0.02, 0.0), Vec3(0.07, 0.05, 0.03)};
  ObjectModel m = test::box_model(box, Vec3(0, 0, 0), 0.08, 3, {{Box3{Vec3(0, 0, 0), Vec3(0.03, 0.03, 0.03)}, 5}});
  std::vector<Vec3> xs;
  m.dofs().prolong(m.dofs().dof_rest, xs);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int i = 0; i < 1000; ++i) {
    const Vec3 X = box.min + (box.max - box.min).cwiseProduct(Vec3(u(rng), u(rng), u(rng)));
    const auto e = m.embed(X);
    ASSERT_TRUE(e);
    EXPECT_LT((m.evaluate(*e, xs) - X).norm(), 1e-15);
  }
  // A point on the outer boundary face is still embedded, a point outside the root is not.
  EXPECT_TRUE(m.embed(Vec3(0.07, 0.04, 0.03)));
  EXPECT_FALSE(m.embed(Vec3(0.5, 0.5, 0.5)));
}

}  // namespace
}  // namespace octocut::sim
