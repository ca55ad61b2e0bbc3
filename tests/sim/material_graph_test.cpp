// Material graph M: exact tet–box clipping against analytic volumes and conservation, connectivity on hand-built
// tet configurations, and the octree built from M against the exact box material.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "octocut/sim/material_graph.hpp"
#include "../common/kuhn_grid.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

// The corner tet {x, y, z >= 0, x + y + z <= 1}.
const std::array<Vec3, 4> kCorner{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};

double cube3(double v) { return v > 0.0 ? v * v * v : 0.0; }

using octocut::test::kuhn_box;

TEST(TetClip, CornerTetInCubeMatchesInclusionExclusion) {
  // Volume of {x + y + z <= 1} within [0, a]^3 by inclusion–exclusion over the faces x = a, y = a, z = a.
  for (double a : {0.1, 0.3, 0.5, 0.7, 0.999, 1.0, 1.5}) {
    const double expected = (1.0 - 3 * cube3(1 - a) + 3 * cube3(1 - 2 * a) - cube3(1 - 3 * a)) / 6.0;
    const double got = clip_tet_box_volume(kCorner, Box3{Vec3::Zero(), Vec3::Constant(a)});
    EXPECT_NEAR(got, expected, 1e-15) << "a = " << a;
  }
}

TEST(TetClip, RandomTetsArePartitionedByAGridOfBoxes) {
  // Clipped volumes over a grid of boxes that tiles space around the tet sum to the tet's volume.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    std::array<Vec3, 4> t{};
    for (auto& p : t) p = Vec3(u(rng), u(rng), u(rng));
    const double volume = std::abs((t[1] - t[0]).dot((t[2] - t[0]).cross(t[3] - t[0]))) / 6.0;
    double sum = 0.0;
    const int n = 7;
    const double h = 2.0 / n;
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          const Vec3 lo(-1 + i * h, -1 + j * h, -1 + k * h);
          sum += clip_tet_box_volume(t, Box3{lo, lo + Vec3::Constant(h)});
        }
    EXPECT_NEAR(sum, volume, 1e-14 * std::max(1.0, volume)) << "trial " << trial;
  }
}

TEST(TetClip, BoxApartOrAroundGivesZeroOrAll) {
  EXPECT_EQ(clip_tet_box_volume(kCorner, Box3{Vec3(2, 2, 2), Vec3(3, 3, 3)}), 0.0);
  EXPECT_NEAR(clip_tet_box_volume(kCorner, Box3{Vec3::Constant(-1), Vec3::Constant(2)}), 1.0 / 6.0, 1e-16);
}

TEST(TetSection, AreaOfAxisSectionIsAnalytic) {
  // The corner tet cut by z = c is the right triangle with legs 1 − c; a face rectangle [0, s]^2 keeps
  // the part with x + y <= 1 − c.
  const double c = 0.25, legs = 0.75;
  Box3 face{Vec3(-1, -1, c), Vec3(2, 2, c)};
  EXPECT_NEAR(tet_face_section_area(kCorner, face, 2), 0.5 * legs * legs, 1e-15);
  const double s = 0.5;  // square [0, 0.5]^2 cut by x + y <= 0.75: loses a corner triangle of legs 0.25
  face = Box3{Vec3(0, 0, c), Vec3(s, s, c)};
  EXPECT_NEAR(tet_face_section_area(kCorner, face, 2), s * s - 0.5 * 0.25 * 0.25, 1e-15);
}

TEST(MaterialGraphConnectivity, EdgeContactIsNotConnectedFaceAreaIs) {
  // Two tets on either side of the plane x = 0 that share only the edge (0,0,0)–(0,1,0) lying in the plane.
  TetMesh edge_only;
  edge_only.vertices = {Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(-1, 0, 0.5), Vec3(-1, 0, -0.5), Vec3(1, 0, 0.5),
                        Vec3(1, 0, -0.5)};
  edge_only.tets = {{0, 1, 2, 3}, {0, 1, 4, 5}};
  const MaterialGraph g(edge_only);
  const Box3 face{Vec3(0, -1, -1), Vec3(0, 2, 2)};
  EXPECT_FALSE(g.face_connected(face, 0));
  // The leaves on either side both hold material nonetheless.
  EXPECT_GT(g.occupancy(Box3{Vec3(-1, -1, -1), Vec3(0, 2, 2)}), 0.0);
  EXPECT_GT(g.occupancy(Box3{Vec3(0, -1, -1), Vec3(1, 2, 2)}), 0.0);

  // Two tets sharing the triangle (0,0,0), (0,1,0), (0,0,1) in the plane x = 0: connected.
  TetMesh shared_face;
  shared_face.vertices = {Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1), Vec3(-1, 0, 0), Vec3(1, 0, 0)};
  shared_face.tets = {{0, 1, 2, 3}, {0, 1, 2, 4}};
  EXPECT_TRUE(MaterialGraph(shared_face).face_connected(face, 0));
  // A face rectangle that only touches the shared triangle at its corner vertex: not connected.
  EXPECT_FALSE(MaterialGraph(shared_face).face_connected(Box3{Vec3(0, -1, -1), Vec3(0, 0, 0)}, 0));

  // One tet crossing the plane: its section has positive area, so the faces it crosses are connected.
  TetMesh crossing;
  crossing.vertices = {Vec3(-1, 0, 0), Vec3(1, 0.1, 0), Vec3(0, 1, 0.1), Vec3(0.1, 0.1, 1)};
  crossing.tets = {{0, 1, 2, 3}};
  EXPECT_TRUE(MaterialGraph(crossing).face_connected(face, 0));
  // ... but not a face rectangle beside the section.
  EXPECT_FALSE(MaterialGraph(crossing).face_connected(Box3{Vec3(0, 1.5, 1.5), Vec3(0, 2, 2)}, 0));
}

TEST(MaterialGraphOccupancy, SumOverAllLeavesEqualsTetVolume) {
  // A jittered tet mesh of a box, not aligned with the octree; sum occupancy × cell volume over every cell of a
  // uniform level (empty ones included).
  const Box3 box{Vec3(0.013, 0.021, 0.007), Vec3(0.071, 0.052, 0.043)};
  const MaterialGraph g(kuhn_box(box, 6, 0.3, 3));
  const RootGeometry root{Vec3::Zero(), 0.08};
  const int level = 4, n = 1 << level;
  double sum = 0.0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double h = root.size / n;
        const Vec3 lo = root.min + h * Vec3(i, j, k);
        const Box3 cell{lo, lo + Vec3::Constant(h)};
        sum += g.occupancy(cell) * cell.volume();
      }
  EXPECT_NEAR(sum, g.volume(), 1e-12 * g.volume());
  // The tets tile the box exactly, so their volume is the box's.
  EXPECT_NEAR(g.volume(), box.volume(), 1e-12 * box.volume());
}

TEST(MaterialGraphOccupancy, OctreeFromTetsOfABoxMatchesTheExactBoxMaterial) {
  // A tet mesh that tiles a box describes the same material as the box itself: same leaves, occupancies and DOFs.
  const Box3 box{Vec3(0.0, 0.0, 0.0), Vec3(0.05, 0.02, 0.03)};
  OctreeSpec spec;
  spec.root = {Vec3(-0.004, -0.003, -0.002), 0.06};
  spec.base_level = 4;
  spec.max_level = 6;
  spec.refine = {{Box3{Vec3(0.0, 0.0, 0.0), Vec3(0.01, 0.02, 0.03)}, 6}};
  const auto tets = std::make_shared<MaterialGraph>(kuhn_box(box, 5, 0.25, 11));
  const ObjectModel a = ObjectModel::build(spec, tets, {}, {});
  const ObjectModel b = ObjectModel::build(spec, std::make_shared<BoxMaterial>(box), {}, {});
  ASSERT_EQ(a.num_elements(), b.num_elements());
  for (int e = 0; e < a.num_elements(); ++e) {
    ASSERT_EQ(a.tree().leaf(e).morton(), b.tree().leaf(e).morton());
    EXPECT_NEAR(a.occupancy()[std::size_t(e)], b.occupancy()[std::size_t(e)], 1e-12) << "leaf " << e;
  }
  EXPECT_EQ(a.num_dofs(), b.num_dofs());
  EXPECT_EQ(a.dofs().hanging_slots, b.dofs().hanging_slots);
  EXPECT_NEAR(a.volume(), box.volume(), 1e-12 * box.volume());
}

TEST(MaterialGraph, GridQueriesMatchBruteForce) {
  // tets_near and face_connected go through the grid (each tet filed in several cells, reported once); brute
  // force tests every tet. Random boxes and faces of random sizes, some aligned with the Kuhn grid's planes.
  const Box3 box{Vec3(0.0, 0.0, 0.0), Vec3(0.06, 0.04, 0.05)};
  for (const double jitter : {0.0, 0.3}) {
    const MaterialGraph g(kuhn_box(box, 6, jitter, 5));
    std::mt19937 rng(19);
    std::uniform_real_distribution<double> u(-0.01, 0.07), size(0.0, 0.03);
    for (int q = 0; q < 300; ++q) {
      Box3 b;
      b.min = Vec3(u(rng), u(rng), u(rng));
      // Every third query snaps its corner to the tet grid (planes where tets meet), where ties are likeliest.
      if (q % 3 == 0) b.min = (b.min / 0.01).array().round().matrix() * 0.01;
      b.max = b.min + Vec3(size(rng), size(rng), size(rng));
      std::vector<int> brute;
      for (int t = 0; t < g.num_tets(); ++t) {
        Vec3 lo = g.tet(t)[0], hi = lo;
        for (const Vec3& p : g.tet(t)) {
          lo = lo.cwiseMin(p);
          hi = hi.cwiseMax(p);
        }
        if ((hi.array() >= b.min.array()).all() && (lo.array() <= b.max.array()).all()) brute.push_back(t);
      }
      ASSERT_EQ(g.tets_near(b), brute) << "query " << q;

      // The face of b's lower side along a random axis.
      const int axis = q % 3;
      Box3 face = b;
      face.max[axis] = face.min[axis];
      const int v = (axis + 1) % 3, w = (axis + 2) % 3;
      const double threshold = 1e-12 * (face.max[v] - face.min[v]) * (face.max[w] - face.min[w]);
      bool connected = false;
      for (int t = 0; t < g.num_tets(); ++t) connected = connected || tet_face_section_area(g.tet(t), face, axis) > threshold;
      EXPECT_EQ(g.face_connected(face, axis), connected) << "query " << q;
    }
  }
}

TEST(MaterialGraph, RejectsBadInput) {
  TetMesh m;
  EXPECT_THROW(MaterialGraph{m}, std::invalid_argument);
  m.vertices = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, std::nan(""))};
  m.tets = {{0, 1, 2, 3}};
  EXPECT_THROW(MaterialGraph{m}, std::invalid_argument);
  m.vertices[3] = Vec3(0, 0, 1);
  m.tets = {{0, 1, 2, 4}};
  EXPECT_THROW(MaterialGraph{m}, std::invalid_argument);
  // A negatively oriented tet is reoriented, not rejected.
  m.tets = {{0, 2, 1, 3}};
  EXPECT_NEAR(MaterialGraph(m).volume(), 1.0 / 6.0, 1e-16);
}


// ---------------------------------------------------------------------------------------------------------------
// Removing tets (cut stage 3): MaterialGraph::without.

TEST(MaterialGraphWithout, OccupancyDropsByExactlyTheClippedVolumeOfTheRemovedTets) {
  const Box3 box{Vec3(0.0, 0.0, 0.0), Vec3(0.04, 0.03, 0.02)};
  // Jitter small enough that no tet inverts: the tets tile the box without overlap, so no occupancy is clamped.
  const MaterialGraph g(kuhn_box(box, 6, 0.1, 5));
  ASSERT_NEAR(g.volume(), box.volume(), 1e-12 * box.volume());
  // Remove the tets near a small region and every 7th tet elsewhere.
  std::vector<int> removed = g.tets_near(Box3{Vec3(0.01, 0.01, 0.005), Vec3(0.02, 0.015, 0.01)});
  for (int t = 0; t < g.num_tets_total(); t += 7) removed.push_back(t);
  std::sort(removed.begin(), removed.end());
  removed.erase(std::unique(removed.begin(), removed.end()), removed.end());
  const auto h = g.without(removed);
  EXPECT_EQ(h->num_tets(), g.num_tets() - int(removed.size()));
  EXPECT_EQ(h->num_tets_total(), g.num_tets_total());
  double removed_volume = 0.0;
  for (int t : removed) removed_volume += g.tet_volume(t);
  EXPECT_NEAR(h->volume(), g.volume() - removed_volume, 1e-15);
  // Octree-like cells of two sizes, unaligned with the tets.
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-0.005, 0.04);
  for (int n = 0; n < 200; ++n) {
    const Vec3 lo(u(rng), u(rng), u(rng));
    const Box3 cell{lo, lo + Vec3::Constant(n % 2 ? 0.004 : 0.011)};
    double clipped = 0.0;
    for (int t : removed) clipped += clip_tet_box_volume(g.tet(t), cell);
    EXPECT_NEAR((g.occupancy(cell) - h->occupancy(cell)) * cell.volume(), clipped, 1e-12 * cell.volume())
        << "cell " << n;
  }
  for (int t = 0; t < g.num_tets_total(); ++t)
    ASSERT_EQ(h->alive(t), !std::binary_search(removed.begin(), removed.end(), t));
}

TEST(MaterialGraphWithout, FaceConnectivityDropsWhenTheOnlyTetsMeetingTheFaceAreRemoved) {
  // Two tets sharing the triangle (0,0,0), (0,1,0), (0,0,1) in the plane x = 0, and one tet far away.
  TetMesh m;
  m.vertices = {Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1), Vec3(-1, 0, 0), Vec3(1, 0, 0),
                Vec3(5, 5, 5), Vec3(6, 5, 5), Vec3(5, 6, 5), Vec3(5, 5, 6)};
  m.tets = {{0, 1, 2, 3}, {0, 1, 2, 4}, {5, 6, 7, 8}};
  const auto g = std::make_shared<const MaterialGraph>(m);
  const Box3 face{Vec3(0, -1, -1), Vec3(0, 2, 2)};
  ASSERT_TRUE(g->face_connected(face, 0));
  const std::vector<int> one{0}, both{0, 1}, far{2};
  // Either tet alone still meets the face in its shared triangle.
  EXPECT_TRUE(g->without(one)->face_connected(face, 0));
  EXPECT_TRUE(g->without(far)->face_connected(face, 0));
  EXPECT_FALSE(g->without(both)->face_connected(face, 0));
  // Removal composes: removing the second from the graph without the first.
  EXPECT_FALSE(g->without(one)->without(std::vector<int>{1})->face_connected(face, 0));
  // The leaf on the +x side loses its material with tet 1.
  const Box3 plus{Vec3(0, -1, -1), Vec3(1, 2, 2)};
  EXPECT_GT(g->without(one)->occupancy(plus), 0.0);
  EXPECT_EQ(g->without(std::vector<int>{1})->occupancy(plus), 0.0);
}

TEST(MaterialGraphWithout, TheOriginalIsUnchangedAndTheGeometryIsShared) {
  const MaterialGraph g(kuhn_box(Box3{Vec3::Zero(), Vec3::Constant(0.01)}, 4, 0.2, 3));
  const Box3 cell{Vec3::Constant(0.002), Vec3::Constant(0.006)};
  const double occ = g.occupancy(cell), vol = g.volume();
  const std::vector<int> near = g.tets_near(cell);
  const auto h = g.without(near);
  EXPECT_EQ(g.occupancy(cell), occ);
  EXPECT_EQ(g.volume(), vol);
  EXPECT_EQ(g.num_tets(), g.num_tets_total());
  EXPECT_EQ(g.tets_near(cell), near);
  EXPECT_EQ(h->occupancy(cell), 0.0);
  EXPECT_TRUE(h->tets_near(cell).empty());
  // The revision shares the mesh (same object), which therefore still lists every tet; live_mesh() lists the rest.
  EXPECT_EQ(&h->mesh(), &g.mesh());
  EXPECT_EQ(int(h->mesh().tets.size()), g.num_tets_total());
  const TetMesh live = h->live_mesh();
  EXPECT_EQ(int(live.tets.size()), h->num_tets());
  EXPECT_NEAR(MaterialGraph(live).volume(), h->volume(), 1e-18);
  // Duplicates and tets already dead are fine; an index out of range is not.
  const std::vector<int> again{near[0], near[0]};
  EXPECT_EQ(h->without(again)->num_tets(), h->num_tets());
  EXPECT_THROW((void)g.without(std::vector<int>{g.num_tets_total()}), std::invalid_argument);
  EXPECT_THROW((void)g.without(std::vector<int>{-1}), std::invalid_argument);
}

TEST(MaterialGraphWithout, RemovingEverythingLeavesNoMaterial) {
  const Box3 box{Vec3::Zero(), Vec3(0.02, 0.01, 0.01)};
  const MaterialGraph g(kuhn_box(box, 3, 0.2, 1));
  std::vector<int> all(std::size_t(g.num_tets_total()));
  for (int t = 0; t < g.num_tets_total(); ++t) all[std::size_t(t)] = t;
  const auto h = g.without(all);
  EXPECT_EQ(h->num_tets(), 0);
  EXPECT_EQ(h->volume(), 0.0);
  EXPECT_EQ(h->occupancy(box), 0.0);
  EXPECT_FALSE(h->face_connected(Box3{Vec3(0.01, 0, 0), Vec3(0.01, 0.01, 0.01)}, 0));
  EXPECT_TRUE(h->tets_near(box).empty());
  EXPECT_TRUE((h->bounds().min.array() <= h->bounds().max.array()).all());
  // ... and the full graph still fills the box.
  EXPECT_NEAR(g.occupancy(box), 1.0, 1e-12);
}

}  // namespace
}  // namespace octocut::sim
