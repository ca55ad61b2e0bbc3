// The Z-curve surface embedding (SPEC §2.4, paper §4.5) against independent truths: brute-force Morton codes and
// range queries, exact reproduction of rest and affine fields (with hanging nodes), analytic normals of an affinely
// deformed closed mesh, the fallback rule, and incremental updates against a rebuild from scratch.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <set>

#include "octocut/sim/embedding.hpp"
#include "octocut/sim/naive_embedding.hpp"
#include "octocut/sim/surface.hpp"
#include "../common/shapes.hpp"
#include "test_util.hpp"

namespace octocut::sim {
namespace {

// The shared procedural ellipsoid.
TriMesh ellipsoid(const Vec3& centre, const Vec3& radii, int segments, int rings) {
  return octocut::test::ellipsoid_mesh(centre, radii, segments, rings);
}

// Bit-by-bit Morton interleave (x lowest), independent of the octree's magic-number version.
std::uint64_t morton_brute(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  std::uint64_t code = 0;
  for (int b = 0; b < 21; ++b) {
    code |= std::uint64_t((x >> b) & 1u) << (3 * b);
    code |= std::uint64_t((y >> b) & 1u) << (3 * b + 1);
    code |= std::uint64_t((z >> b) & 1u) << (3 * b + 2);
  }
  return code;
}

// Finest grid cell of p by long-double arithmetic, clamped to the grid.
GridPoint cell_brute(const RootGeometry& root, const Vec3& p) {
  GridPoint g;
  std::uint32_t* out[3] = {&g.x, &g.y, &g.z};
  for (int d = 0; d < 3; ++d) {
    const long double t = (static_cast<long double>(p[d]) - root.min[d]) / root.size * (1u << kMaxDepth);
    const long double f = std::floor(t);
    *out[d] = std::uint32_t(std::clamp(f, 0.0L, static_cast<long double>(kGridCells - 1)));
  }
  return g;
}

// A 16 mm root with a 12 mm box of material, 2 mm leaves, and one corner refined to level 5 (0.5 mm): neighbours
// differ by two levels, so there are hanging nodes bound across an unrestricted jump.
const RootGeometry kRoot{Vec3::Zero(), 0.016};
ObjectModel hanging_model() {
  return test::box_model({Vec3::Constant(0.002), Vec3::Constant(0.014)}, kRoot.min, kRoot.size, 3,
                         {{{Vec3(0.008, 0.008, 0.008), Vec3(0.012, 0.012, 0.012)}, 5}});
}
const Vec3 kCentre(0.008, 0.0082, 0.0079);
const Vec3 kRadii(0.0051, 0.0043, 0.0037);

const Mat3 kA = (Mat3() << 1.1, 0.2, -0.1, 0.05, 0.9, 0.15, -0.2, 0.1, 1.2).finished();
const Vec3 kB(0.01, -0.02, 0.005);

std::vector<Vec3> affine_dofs(const ObjectModel& m) {
  std::vector<Vec3> x;
  for (const Vec3& X : m.dofs().dof_rest) x.push_back(kA * X + kB);
  return x;
}

void expect_same(const SurfaceEmbedding& a, const SurfaceEmbedding& b) {
  EXPECT_EQ(a.zcurve().entries(), b.zcurve().entries());
  ASSERT_EQ(a.num_vertices(), b.num_vertices());
  for (int v = 0; v < a.num_vertices(); ++v) {
    EXPECT_EQ(a.rest_vertices()[std::size_t(v)], b.rest_vertices()[std::size_t(v)]);
    EXPECT_EQ(a.embeddings()[std::size_t(v)], b.embeddings()[std::size_t(v)]) << "vertex " << v;
  }
  EXPECT_EQ(a.dof_begin(), b.dof_begin());
  EXPECT_EQ(a.dof_index(), b.dof_index());
  EXPECT_EQ(a.dof_weight(), b.dof_weight());
  EXPECT_EQ(a.triangles(), b.triangles());
}

TEST(ZCurve, CodesOrderAndRangeQueriesMatchBruteForce) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-0.001, 0.017);  // a few points outside the root, clamped
  std::vector<Vec3> pts(5000);
  for (Vec3& p : pts) p = Vec3(u(rng), u(rng), u(rng));
  // Points on grid planes, where floor and clamping matter.
  pts[0] = kRoot.min;
  pts[1] = kRoot.min + Vec3::Constant(kRoot.size);
  pts[2] = Vec3(0.008, 0.004, 0.012);
  const ZCurveList list(kRoot, pts);

  // Every vertex once, codes equal to the bit-by-bit interleave, sorted by (code, vertex).
  ASSERT_EQ(list.size(), int(pts.size()));
  std::vector<int> seen(pts.size(), 0);
  for (std::size_t i = 0; i < list.entries().size(); ++i) {
    const ZEntry& e = list.entries()[i];
    ++seen[std::size_t(e.vertex)];
    const GridPoint g = cell_brute(kRoot, pts[std::size_t(e.vertex)]);
    EXPECT_EQ(e.code, morton_brute(g.x, g.y, g.z));
    if (i > 0) {
      EXPECT_TRUE(list.entries()[i - 1] < e);
    }
  }
  EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](int s) { return s == 1; }));

  // Range queries of random cells on levels 0..10 against a scan of all points.
  for (int q = 0; q < 300; ++q) {
    const int level = int(rng() % 11);
    const GridPoint g = cell_brute(kRoot, pts[rng() % pts.size()]);
    const std::uint32_t s = kGridCells >> level;
    const Cell c{{g.x / s * s, g.y / s * s, g.z / s * s}, level};
    std::set<int> brute, fast;
    for (std::size_t v = 0; v < pts.size(); ++v)
      if (c.contains_cell(cell_brute(kRoot, pts[v]))) brute.insert(int(v));
    for (const ZEntry& e : list.in_cell(c)) fast.insert(e.vertex);
    EXPECT_EQ(fast, brute) << "level " << level;
    EXPECT_FALSE(brute.empty());
  }
}

TEST(SurfaceEmbedding, LeafRangesPartitionTheVerticesLikeTheNaiveOctree) {
  const ObjectModel m = hanging_model();
  const TriMesh s = ellipsoid(kCentre, kRadii, 48, 24);
  const SurfaceEmbedding e(m, s.vertices, s.triangles);
  const NaiveEmbedding naive(m.tree(), m.root(), s.vertices);
  EXPECT_EQ(naive.num_entries() > s.vertices.size(), true);
  std::size_t total = 0;
  for (int l = 0; l < m.num_elements(); ++l) {
    std::vector<int> z;
    for (const ZEntry& en : e.vertices_in_leaf(l)) {
      z.push_back(en.vertex);
      EXPECT_EQ(e.embeddings()[std::size_t(en.vertex)].leaf, l);
      // The rest point lies in the leaf's closed box.
      EXPECT_TRUE(m.root().cell_box(m.tree().leaf(l)).contains(s.vertices[std::size_t(en.vertex)], 1e-15));
    }
    std::sort(z.begin(), z.end());
    const auto nl = naive.vertices_in_leaf(l);
    EXPECT_EQ(z, std::vector<int>(nl.begin(), nl.end())) << "leaf " << l;
    total += z.size();
  }
  EXPECT_EQ(total, s.vertices.size());
  EXPECT_EQ(e.num_fallback(), 0);
}

TEST(SurfaceEmbedding, ReproducesRestAndAffineFieldsWithHangingNodes) {
  const ObjectModel m = hanging_model();
  ASSERT_GT(m.dofs().hanging_slots, 0);
  const TriMesh s = ellipsoid(kCentre, kRadii, 48, 24);
  const SurfaceEmbedding e(m, s.vertices, s.triangles);
  Executor exec(1);
  std::vector<Vec3> p;
  // At rest the vertices come back where they are.
  e.deformed_positions(m.dofs().dof_rest, p, exec);
  for (std::size_t v = 0; v < p.size(); ++v) EXPECT_LT((p[v] - s.vertices[v]).norm(), 1e-15) << v;
  // Some vertices sit in leaves whose slots are hard-bound: their composed lists reach beyond 8 DOFs' own corners.
  int bound = 0;
  for (int v = 0; v < e.num_vertices(); ++v) {
    const int leaf = e.embeddings()[std::size_t(v)].leaf;
    for (int k = 0; k < 8; ++k) bound += m.dofs().slot_master[std::size_t(8 * leaf + k)] >= 0 ? 1 : 0;
  }
  EXPECT_GT(bound, 0);
  // An affine field on the DOFs is reproduced exactly.
  e.deformed_positions(affine_dofs(m), p, exec);
  for (std::size_t v = 0; v < p.size(); ++v) EXPECT_LT((p[v] - (kA * s.vertices[v] + kB)).norm(), 1e-15) << v;
}

TEST(SurfaceEmbedding, NormalsOfAnAffinelyDeformedClosedMeshAreAnalytic) {
  const ObjectModel m = hanging_model();
  const TriMesh s = ellipsoid(kCentre, kRadii, 48, 24);
  ASSERT_GT(signed_volume(s), 0.0);
  const SurfaceEmbedding e(m, s.vertices, s.triangles);
  Executor exec(1);
  std::vector<Vec3> p, n;
  e.deformed_positions(affine_dofs(m), p, exec);
  e.deformed_normals(p, n, exec);
  // Area-weighted face normals transform with the cofactor det(A) A^-T, so the vertex normals are A^-T n_rest.
  const std::vector<Vec3> rest_n = vertex_normals(s.vertices, s.triangles);
  const Mat3 cof = kA.inverse().transpose();
  for (std::size_t v = 0; v < n.size(); ++v) {
    const Vec3 expected = (cof * rest_n[v]).normalized();
    EXPECT_LT((n[v] - expected).norm(), 1e-9) << v;
  }
  // And they are the plain serial vertex normals of the deformed mesh, bit for bit.
  EXPECT_EQ(n, vertex_normals(p, s.triangles));
}

TEST(SurfaceEmbedding, FallbackVerticesBindToTheNearestLeafWithClampedWeights) {
  // Leaves exactly cover [2, 14] mm; the triangle's vertices lie outside all of them.
  const ObjectModel m = test::box_model({Vec3::Constant(0.002), Vec3::Constant(0.014)}, kRoot.min, kRoot.size, 3);
  const std::vector<Vec3> rest{Vec3(0.0145, 0.008, 0.0091),  // 0.5 mm beyond a face, on a leaf boundary in y
                               Vec3(0.0159, 0.0158, 0.0157),  // far beyond a corner: the weights must be clamped
                               Vec3(0.010, 0.009, 0.011)};    // inside
  const SurfaceEmbedding e(m, rest, {{0, 1, 2}});
  EXPECT_EQ(e.num_fallback(), 2);
  for (int v = 0; v < 2; ++v) {
    const VertexEmbedding& ve = e.embeddings()[std::size_t(v)];
    EXPECT_TRUE(ve.fallback);
    // The nearest leaf by brute force, the lowest index among equals.
    double best = 1e9;
    int leaf = -1;
    for (int l = 0; l < m.num_elements(); ++l) {
      const Box3 b = m.root().cell_box(m.tree().leaf(l));
      const double d = (b.min - rest[std::size_t(v)]).cwiseMax(rest[std::size_t(v)] - b.max).cwiseMax(0.0).norm();
      if (d < best - 1e-18) best = d, leaf = l;
    }
    EXPECT_EQ(ve.leaf, leaf);
    double sum = 0.0;
    for (double w : ve.weights) {
      EXPECT_GE(w, kFallbackWeightMin);
      EXPECT_LE(w, kFallbackWeightMax);
      sum += w;
    }
    EXPECT_NEAR(sum, 1.0, 1e-14);
  }
  // The near vertex keeps its exact extrapolated weights (all inside the range), so affine fields still hold there.
  Executor exec(1);
  std::vector<Vec3> p;
  e.deformed_positions(affine_dofs(m), p, exec);
  EXPECT_LT((p[0] - (kA * rest[0] + kB)).norm(), 1e-15);
  EXPECT_LT((p[2] - (kA * rest[2] + kB)).norm(), 1e-15);
  // The far vertex: raw trilinear weights reach 1.95^3; the clamped ones hit both bounds.
  const auto& w1 = e.embeddings()[1].weights;
  EXPECT_EQ(*std::max_element(w1.begin(), w1.end()), kFallbackWeightMax);
  EXPECT_EQ(*std::min_element(w1.begin(), w1.end()), kFallbackWeightMin);
}

TEST(SurfaceEmbedding, FallbackSearchMatchesTheBruteForceScan) {
  // Two separate blocks of 0.5 mm leaves (3400 of them); points inside, between, around and beyond the root, some on
  // the leaf lattice where distances tie.
  OctreeSpec spec;
  spec.root = kRoot;
  spec.base_level = 5;
  spec.max_level = 6;
  const ObjectModel m = ObjectModel::build(
      spec,
      std::make_shared<BoxSetMaterial>(std::vector<Box3>{{Vec3(0.002, 0.003, 0.001), Vec3(0.009, 0.013, 0.006)},
                                                         {Vec3(0.011, 0.0105, 0.0095), Vec3(0.015, 0.0145, 0.0135)}}),
      {}, {});
  ASSERT_GT(m.num_elements(), 2000);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-0.004, 0.020);
  std::uniform_int_distribution<int> lattice(-4, 36);
  std::vector<Vec3> pts;
  for (int i = 0; i < 1500; ++i) pts.push_back(Vec3(u(rng), u(rng), u(rng)));
  for (int i = 0; i < 500; ++i) pts.push_back(0.0005 * Vec3(lattice(rng), lattice(rng), lattice(rng)));
  const SurfaceEmbedding e(m, pts, {});
  EXPECT_GT(e.num_fallback(), 1000);
  for (std::size_t v = 0; v < pts.size(); ++v)
    EXPECT_EQ(e.embeddings()[v], embed_vertex(m.tree(), m.root(), pts[v])) << "point " << v;
}

TEST(SurfaceEmbedding, ClampedWeightsAreTheProjectionOntoTheRange) {
  // KKT conditions of the Euclidean projection onto {lo <= w <= hi, sum w = 1}: w = clamp(raw - shift) for one shift.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.5, 2.5);
  for (int t = 0; t < 200; ++t) {
    const auto raw = trilinear_weights(Vec3(u(rng), u(rng), u(rng)));
    const auto w = clamp_fallback_weights(raw);
    double sum = 0.0, shift = 0.0;
    bool have_free = false;
    for (std::size_t k = 0; k < 8; ++k) {
      sum += w[k];
      if (w[k] > kFallbackWeightMin && w[k] < kFallbackWeightMax) shift = raw[k] - w[k], have_free = true;
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    if (!have_free) continue;
    for (std::size_t k = 0; k < 8; ++k)
      EXPECT_NEAR(w[k], std::clamp(raw[k] - shift, kFallbackWeightMin, kFallbackWeightMax), 1e-12);
  }
}

// A cut near the +x end of the ellipsoid: the vertices within `radius` of the spot go, `count` new ones come inside
// the ball (or, for a batch, anywhere in the material), and the leaves around the spot are refined.
struct Cut {
  SurfaceEdit edit;
  std::vector<Vec3> new_rest;
  ObjectModel new_model;
};

Cut make_cut(const ObjectModel& m, const TriMesh& s, int count, bool spread, bool refine) {
  const Vec3 spot = kCentre + Vec3(kRadii.x(), 0, 0);
  const double radius = 0.0015;
  Cut c{{}, {}, m};
  std::vector<int> map(s.vertices.size(), -1);
  int next = 0;
  for (std::size_t v = 0; v < s.vertices.size(); ++v) {
    if ((s.vertices[v] - spot).norm() < radius)
      c.edit.removed_vertices.push_back(int(v));
    else
      map[v] = next++, c.new_rest.push_back(s.vertices[v]);
  }
  // Removed in descending order: any order must do.
  std::reverse(c.edit.removed_vertices.begin(), c.edit.removed_vertices.end());
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < count; ++i) {
    const Vec3 d(u(rng), u(rng), u(rng));
    const Vec3 p = spread ? Vec3(Vec3(0.008, 0.008, 0.008) + 0.0059 * d)
                          : Vec3(spot - Vec3(0.8 * radius, 0, 0) + 0.7 * radius * d);
    c.edit.inserted_rest.push_back(p);
    c.new_rest.push_back(p);
  }
  // Triangles among kept vertices survive, renumbered; a fan joins consecutive new vertices.
  for (const auto& t : s.triangles)
    if (map[std::size_t(t[0])] >= 0 && map[std::size_t(t[1])] >= 0 && map[std::size_t(t[2])] >= 0)
      c.edit.triangles.push_back({map[std::size_t(t[0])], map[std::size_t(t[1])], map[std::size_t(t[2])]});
  for (int i = 0; i + 2 < count; ++i) c.edit.triangles.push_back({next + i, next + i + 1, next + i + 2});
  if (refine) {
    // Refine the leaves that meet the ball; then mark the leaves of the new tree that meet it as changed.
    std::vector<int> pick;
    const Box3 ball{spot - Vec3::Constant(radius), spot + Vec3::Constant(radius)};
    for (int l = 0; l < m.num_elements(); ++l)
      if (m.root().cell_box(m.tree().leaf(l)).overlap_volume(ball) > 0.0) pick.push_back(l);
    c.new_model = m.refined(pick);
    for (int l = 0; l < c.new_model.num_elements(); ++l)
      if (c.new_model.root().cell_box(c.new_model.tree().leaf(l)).overlap_volume(ball) > 0.0)
        c.edit.changed_leaves.push_back(l);
  }
  return c;
}

void check_update_equals_rebuild(int count, bool spread, bool refine, bool expect_merge) {
  const ObjectModel m = hanging_model();
  TriMesh s = ellipsoid(kCentre, kRadii, 60, 30);
  // Two loose vertices outside the material near the cut: they fall back, and after refinement to a child leaf.
  s.vertices.push_back(Vec3(0.0147, 0.0060, 0.0079));
  s.vertices.push_back(Vec3(0.0150, 0.0083, 0.0110));
  SurfaceEmbedding e(m, s.vertices, s.triangles);
  ASSERT_EQ(e.num_fallback(), 2);
  const Cut cut = make_cut(m, s, count, spread, refine);
  ASSERT_GT(cut.edit.removed_vertices.size(), 5u);
  const std::vector<int> map = e.update(cut.new_model, cut.edit);
  EXPECT_EQ(e.last_update_merged(), expect_merge);
  // Only part of the surface was re-embedded.
  EXPECT_LT(e.last_reembedded(), e.num_vertices() / 2);
  EXPECT_GE(e.last_reembedded(), count);
  // The map sends kept vertices to their new slots.
  for (std::size_t v = 0; v < map.size(); ++v)
    if (map[v] >= 0) {
      EXPECT_EQ(e.rest_vertices()[std::size_t(map[v])], s.vertices[v]);
    }

  const SurfaceEmbedding fresh(cut.new_model, cut.new_rest, cut.edit.triangles);
  expect_same(e, fresh);
  EXPECT_EQ(e.num_fallback(), 2);
  Executor exec(2);
  std::vector<Vec3> pa, pb, na, nb;
  e.deformed_positions(affine_dofs(cut.new_model), pa, exec);
  fresh.deformed_positions(affine_dofs(cut.new_model), pb, exec);
  EXPECT_EQ(pa, pb);
  e.deformed_normals(pa, na, exec);
  fresh.deformed_normals(pb, nb, exec);
  EXPECT_EQ(na, nb);

  // The naive per-level lists, updated the same way, hold the same leaf sets as the Z-curve ranges.
  NaiveEmbedding naive(m.tree(), m.root(), s.vertices);
  EXPECT_EQ(naive.update(cut.edit.removed_vertices, cut.edit.inserted_rest), map);
  for (int l = 0; l < m.num_elements(); ++l) {
    std::vector<int> z;
    for (const ZEntry& en : e.zcurve().in_cell(m.tree().leaf(l))) z.push_back(en.vertex);
    std::sort(z.begin(), z.end());
    const auto nl = naive.vertices_in_leaf(l);
    EXPECT_EQ(z, std::vector<int>(nl.begin(), nl.end())) << "leaf " << l;
  }
}

TEST(SurfaceEmbedding, UpdateOneByOneEqualsRebuild) { check_update_equals_rebuild(20, false, false, false); }
TEST(SurfaceEmbedding, UpdateOneByOneWithRefinementEqualsRebuild) {
  check_update_equals_rebuild(20, false, true, false);
}
TEST(SurfaceEmbedding, UpdateMergeEqualsRebuild) { check_update_equals_rebuild(400, true, false, true); }
TEST(SurfaceEmbedding, UpdateMergeWithRefinementEqualsRebuild) { check_update_equals_rebuild(400, true, true, true); }

TEST(SurfaceEmbedding, RebindAfterRefinementEqualsRebuild) {
  const ObjectModel m = hanging_model();
  const TriMesh s = ellipsoid(kCentre, kRadii, 48, 24);
  SurfaceEmbedding e(m, s.vertices, s.triangles);
  const ObjectModel r = m.refined({0, 3, m.num_elements() / 2, m.num_elements() - 1});
  e.rebind(r);
  expect_same(e, SurfaceEmbedding(r, s.vertices, s.triangles));
  EXPECT_LT(e.last_reembedded(), e.num_vertices());
}

TEST(SurfaceEmbedding, ThreadCountDoesNotChangeResults) {
  const ObjectModel m = hanging_model();
  const TriMesh s = ellipsoid(kCentre, kRadii, 160, 80);  // ~12.6k vertices: several parallel chunks
  const SurfaceEmbedding e(m, s.vertices, s.triangles);
  // A smooth non-affine field on the DOFs.
  std::vector<Vec3> x;
  for (const Vec3& X : m.dofs().dof_rest)
    x.push_back(X + 0.001 * Vec3(std::sin(400 * X.y()), std::cos(300 * X.z()), std::sin(500 * X.x())));
  Executor one(1), two(2);
  std::vector<Vec3> p1, p2, n1, n2;
  e.deformed_positions(x, p1, one);
  e.deformed_positions(x, p2, two);
  EXPECT_EQ(p1, p2);
  e.deformed_normals(p1, n1, one);
  e.deformed_normals(p2, n2, two);
  EXPECT_EQ(n1, n2);
}

TEST(SurfaceEmbedding, BadInputIsRejectedWithTheOffendingElement) {
  const ObjectModel m = hanging_model();
  const TriMesh s = ellipsoid(kCentre, kRadii, 12, 6);
  auto message = [](auto&& f) {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no exception");
  };
  auto bad_tris = s.triangles;
  bad_tris[3][1] = int32_t(s.vertices.size());
  EXPECT_NE(message([&] { SurfaceEmbedding(m, s.vertices, bad_tris); }).find("triangle 3 corner 1"),
            std::string::npos);
  auto bad_pts = s.vertices;
  bad_pts[5].y() = std::nan("");
  EXPECT_NE(message([&] { SurfaceEmbedding(m, bad_pts, s.triangles); }).find("vertex 5"), std::string::npos);

  // A failed update leaves the embedding as it was.
  SurfaceEmbedding e(m, s.vertices, s.triangles);
  const auto before = e.zcurve().entries();
  SurfaceEdit edit;
  edit.removed_vertices = {4, 7, 4};
  edit.triangles = {};
  EXPECT_NE(message([&] { e.update(m, edit); }).find("removed_vertices[2] = 4 is listed twice"), std::string::npos);
  edit.removed_vertices = {4};
  edit.triangles = {{0, 1, int32_t(s.vertices.size() - 1)}};
  EXPECT_NE(message([&] { e.update(m, edit); }).find("triangle 0 corner 2"), std::string::npos);
  EXPECT_EQ(e.zcurve().entries(), before);
  std::vector<Vec3> p;
  Executor exec(1);
  EXPECT_NE(message([&] { e.deformed_positions({Vec3::Zero()}, p, exec); }).find("DOF positions"), std::string::npos);
}

}  // namespace
}  // namespace octocut::sim
