// Node splitting and hard binding (SPEC §2.3, paper Fig. 3-4).
#include <gtest/gtest.h>

#include <map>

#include "octocut/sim/dof_map.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

const RootGeometry kUnitRoot{Vec3(0, 0, 0), 1.0};

// Number of DOFs at each logical node.
std::map<std::uint64_t, int> dofs_per_node(const DofMap& dm) {
  std::map<std::uint64_t, int> out;
  for (std::uint64_t k : dm.dof_node) ++out[k];
  return out;
}

std::uint64_t key_at(double x, double y, double z) {
  const double s = double(kGridCells);
  return node_key({std::uint32_t(x * s), std::uint32_t(y * s), std::uint32_t(z * s)});
}

TEST(DofMap, UniformGridHasOneDofPerNode) {
  for (int level = 1; level <= 3; ++level) {
    const ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, level);
    const int n = (1 << level) + 1;
    EXPECT_EQ(m.num_dofs(), n * n * n);
    EXPECT_EQ(m.dofs().hanging_slots, 0);
    EXPECT_EQ(m.dofs().check_invariants(), "");
  }
}

TEST(DofMap, OneRefinedOctantOfEight) {
  // 8 leaves at level 1; refine the one at the origin. Hand count: 27 coarse nodes, 19 new nodes of which the 12
  // on the planes x, y or z = 1/2 hang on coarse faces or edges and the 7 others are DOFs.
  const ObjectModel m0 = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, 1);
  const ObjectModel m = m0.refined({0});
  EXPECT_EQ(m.num_elements(), 15);
  EXPECT_EQ(m.num_dofs(), 34);
  EXPECT_EQ(m.dofs().check_invariants(), "");
  // Hanging slots: the face-centre nodes (3) belong to 4 children each... count the slots of the 12 hanging nodes.
  // Each node at (1/2, 1/4, 1/4)-type face points touches 4 children; edge points (1/2, 1/2, 1/4) touch 2;
  // and (1/2, 1/4, 0)-type points on the outer boundary touch 2.
  // Face interior: 3 faces x 1 centre node (1/2,1/4,1/4 etc.) -> 3 nodes x 4 slots; edge midpoints on the three
  // inner edges (1/2,1/2,1/4 etc.) -> 3 nodes x 2 slots; the remaining 6 lie on outer faces -> 6 x 2 slots.
  EXPECT_EQ(m.dofs().hanging_slots, 3 * 4 + 3 * 2 + 6 * 2);
}

TEST(DofMap, LevelJumpsOfOneTwoThreeMatchBruteForce) {
  for (int jump = 1; jump <= 3; ++jump) {
    ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, 2);
    // Refine the leaf at the origin `jump` times (its origin child each time).
    for (int j = 0; j < jump; ++j) m = m.refined({0});
    int max_level = 0;
    for (const Cell& c : m.tree().leaves()) max_level = std::max(max_level, c.level);
    ASSERT_EQ(max_level, 2 + jump);
    EXPECT_EQ(m.dofs().check_invariants(), "");
    EXPECT_EQ(m.num_dofs(), test::brute_force_free_nodes(m.tree())) << "jump " << jump;
    EXPECT_GT(m.dofs().hanging_slots, 0);
  }
}

TEST(DofMap, HangingChainsResolveToTrueDofsAndInterpolateAffineFields) {
  // Deep jumps in a random pattern: refine random leaves repeatedly.
  ObjectModel m = test::box_model({Vec3(0, 0, 0), Vec3(1, 1, 1)}, Vec3(0, 0, 0), 1.0, 1);
  std::mt19937 rng(11);
  for (int round = 0; round < 6; ++round) m = m.refined({int(rng() % unsigned(m.num_elements()))});
  ASSERT_EQ(m.dofs().check_invariants(), "");
  EXPECT_EQ(m.num_dofs(), test::brute_force_free_nodes(m.tree()));
  // P reproduces any affine field exactly at every slot (linear precision of hard binding).
  const Mat3 A = (Mat3() << 1.1, 0.2, -0.3, 0.05, 0.9, 0.1, 0.3, -0.2, 1.2).finished();
  const Vec3 b(0.1, -0.2, 0.3);
  std::vector<Vec3> x(std::size_t(m.num_dofs())), slots;
  for (int d = 0; d < m.num_dofs(); ++d) x[std::size_t(d)] = A * m.dofs().dof_rest[std::size_t(d)] + b;
  m.dofs().prolong(x, slots);
  for (std::size_t s = 0; s < slots.size(); ++s) EXPECT_LT((slots[s] - (A * m.slot_rest()[s] + b)).norm(), 1e-13);
}

// Material made of one box per level-1 octant, retracted by `gap` from the faces listed as cut.
std::shared_ptr<BoxSetMaterial> octant_material(const std::vector<std::pair<int, int>>& cut_faces, double gap) {
  std::vector<Box3> boxes;
  for (int o = 0; o < 8; ++o) {
    Box3 b{Vec3((o & 1) * 0.5, ((o >> 1) & 1) * 0.5, ((o >> 2) & 1) * 0.5), Vec3::Zero()};
    b.max = b.min + Vec3::Constant(0.5);
    for (const auto& [a, c] : cut_faces) {
      if (a != o && c != o) continue;
      const int other = a == o ? c : a;
      const int axis = (o ^ other) == 1 ? 0 : ((o ^ other) == 2 ? 1 : 2);
      // Retract from the shared face: the side toward the other octant.
      if (((other >> axis) & 1) > ((o >> axis) & 1))
        b.max[axis] -= gap;
      else
        b.min[axis] += gap;
    }
    boxes.push_back(b);
  }
  return std::make_shared<BoxSetMaterial>(boxes);
}

// All pairs of face-adjacent octants across the plane `axis` = 1/2, optionally only on one side of another axis.
std::vector<std::pair<int, int>> plane_cut(int axis, int side_axis = -1, int side = 0) {
  std::vector<std::pair<int, int>> out;
  for (int o = 0; o < 8; ++o) {
    const int p = o ^ (1 << axis);
    if (o > p) continue;
    if (side_axis >= 0 && ((o >> side_axis) & 1) != side) continue;
    out.emplace_back(o, p);
  }
  return out;
}

DofMap octant_dofs(const std::vector<std::pair<int, int>>& cuts) {
  std::vector<Cell> cells;
  for (int k = 0; k < 8; ++k) cells.push_back(Cell{}.child(k));
  const Octree tree(cells);
  return build_dof_map(tree, kUnitRoot, *octant_material(cuts, 0.05));
}

TEST(DofMap, NodeSplitsIntoTwoThreeAndFourDofs) {
  const std::uint64_t centre = key_at(0.5, 0.5, 0.5);
  {
    // A full cut along x = 1/2: every node on that plane splits in two.
    const DofMap dm = octant_dofs(plane_cut(0));
    EXPECT_EQ(dofs_per_node(dm)[centre], 2);
    EXPECT_EQ(dm.num_dofs, 27 + 9);
    EXPECT_EQ(dm.check_invariants(), "");
  }
  {
    // x = 1/2 everywhere, y = 1/2 only for x > 1/2: the centre line splits in three.
    auto cuts = plane_cut(0);
    const auto half = plane_cut(1, 0, 1);
    cuts.insert(cuts.end(), half.begin(), half.end());
    const DofMap dm = octant_dofs(cuts);
    EXPECT_EQ(dofs_per_node(dm)[centre], 3);
    EXPECT_EQ(dofs_per_node(dm)[key_at(0.5, 0.5, 0.0)], 3);
    EXPECT_EQ(dm.check_invariants(), "");
  }
  {
    // Two full cuts, x = 1/2 and y = 1/2: 3 nodes on the centre line split in 4, 12 other plane nodes in 2.
    auto cuts = plane_cut(0);
    const auto y = plane_cut(1);
    cuts.insert(cuts.end(), y.begin(), y.end());
    const DofMap dm = octant_dofs(cuts);
    EXPECT_EQ(dofs_per_node(dm)[centre], 4);
    EXPECT_EQ(dm.num_dofs, 27 - 15 + 3 * 4 + 12 * 2);
    EXPECT_EQ(dm.check_invariants(), "");
  }
  {
    // All three planes: every octant is its own piece, 8 DOFs at the centre, 8 x 8 corners in all.
    auto cuts = plane_cut(0);
    for (int a = 1; a < 3; ++a) {
      const auto c = plane_cut(a);
      cuts.insert(cuts.end(), c.begin(), c.end());
    }
    const DofMap dm = octant_dofs(cuts);
    EXPECT_EQ(dofs_per_node(dm)[centre], 8);
    EXPECT_EQ(dm.num_dofs, 64);
  }
}

TEST(DofMap, DiagonalOctantsConnectOnlyThroughFaces) {
  // Paper Fig. 4: two octants that touch only along an edge (no shared face) are separate DOFs at the node.
  std::vector<Box3> boxes = {{Vec3(0, 0, 0), Vec3(0.5, 0.5, 1.0)}, {Vec3(0.5, 0.5, 0), Vec3(1, 1, 1)}};
  std::vector<Cell> cells;
  for (int k : {0, 3, 4, 7}) cells.push_back(Cell{}.child(k));
  const DofMap dm = build_dof_map(Octree(cells), kUnitRoot, BoxSetMaterial(boxes));
  EXPECT_EQ(dofs_per_node(dm)[key_at(0.5, 0.5, 0.5)], 2);
  EXPECT_EQ(dm.num_dofs, 12 + 12);
}

TEST(DofMap, HangingSlotsNeverBindAcrossACut) {
  // Leaf x < 1/2 is coarse (level 1); the x > 1/2 half is refined to level 2. With material connected across
  // x = 1/2 the fine nodes on that plane hang; with the plane cut they become free DOFs of their own.
  auto build = [](double gap) {
    std::vector<Box3> boxes = {{Vec3(0, 0, 0), Vec3(0.5 - gap, 0.5, 0.5)}, {Vec3(0.5 + gap, 0, 0), Vec3(1, 0.5, 0.5)}};
    std::vector<Cell> cells{Cell{}.child(0)};
    for (int k = 0; k < 8; ++k) cells.push_back(Cell{}.child(1).child(k));
    return build_dof_map(Octree(cells), kUnitRoot, BoxSetMaterial(boxes));
  };
  const DofMap joined = build(0.0);
  const DofMap cut = build(0.01);
  EXPECT_EQ(joined.check_invariants(), "");
  EXPECT_EQ(cut.check_invariants(), "");
  // Plane x = 1/2 of the fine side has 3 x 3 nodes; 5 of them are not coarse corners and hang when joined.
  EXPECT_EQ(joined.num_dofs, 8 + 18);
  EXPECT_EQ(cut.num_dofs, 8 + 27);
  EXPECT_EQ(cut.hanging_slots, 0);
  EXPECT_GT(joined.hanging_slots, 0);
}

}  // namespace
}  // namespace octocut::sim
