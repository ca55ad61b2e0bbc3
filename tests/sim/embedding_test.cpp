// The Z-curve surface embedding (SPEC §2.4, paper §4.5) against independent truths: brute-force Morton codes and
// range queries, exact reproduction of rest and affine fields (with hanging nodes), analytic normals of an affinely
// deformed closed mesh, the fallback rule (with material components: brute-force scans over the leaves of one
// block), and incremental updates against a rebuild from scratch.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <set>
#include <type_traits>

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
  EXPECT_EQ(a.num_triangles(), b.num_triangles());
  for (int v = 0; v < a.num_vertices(); ++v)
    EXPECT_EQ(a.embeddings()[std::size_t(v)], b.embeddings()[std::size_t(v)]) << "vertex " << v;
  EXPECT_EQ(a.dof_begin(), b.dof_begin());
  EXPECT_EQ(a.dof_index(), b.dof_index());
  EXPECT_EQ(a.dof_weight(), b.dof_weight());
}

// S after a cut-like edit of `s`: the vertices not in `removed` in their order, then `inserted`, and `triangles`
// (in the new indices).
TriMesh edited(const TriMesh& s, const std::vector<int>& removed, const std::vector<Vec3>& inserted,
               std::vector<std::array<int32_t, 3>> triangles) {
  std::vector<char> gone(s.vertices.size(), 0);
  for (const int v : removed) gone[std::size_t(v)] = 1;
  TriMesh out;
  for (std::size_t v = 0; v < s.vertices.size(); ++v)
    if (!gone[v]) out.vertices.push_back(s.vertices[v]);
  out.vertices.insert(out.vertices.end(), inserted.begin(), inserted.end());
  out.triangles = std::move(triangles);
  return out;
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
  const SurfaceEmbedding e(m, s);
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
  const SurfaceEmbedding e(m, s);
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
  const SurfaceEmbedding e(m, s);
  Executor exec(1);
  std::vector<Vec3> p, n;
  e.deformed_positions(affine_dofs(m), p, exec);
  e.deformed_normals(s, p, n, exec);
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

// S has one owner: the embedding offers no copy of it, cannot be built from loose arrays, and reads S's triangles
// from the surface it is given (the normals of S with every triangle turned over point the other way).
template <class E>
concept OffersRestVertices = requires(const E& e) { e.rest_vertices(); };
template <class E>
concept OffersTriangles = requires(const E& e) { e.triangles(); };
static_assert(!OffersRestVertices<SurfaceEmbedding> && !OffersTriangles<SurfaceEmbedding>);
static_assert(!std::is_constructible_v<SurfaceEmbedding, const ObjectModel&, std::vector<Vec3>,
                                       std::vector<std::array<int32_t, 3>>>);

TEST(SurfaceEmbedding, ReadsTheTrianglesOfTheSurfaceItIsGiven) {
  const ObjectModel m = hanging_model();
  const TriMesh s = ellipsoid(kCentre, kRadii, 48, 24);
  const SurfaceEmbedding e(m, s);
  EXPECT_TRUE(e.matches(s));
  TriMesh flipped = s;
  for (auto& t : flipped.triangles) std::swap(t[1], t[2]);
  Executor exec(1);
  std::vector<Vec3> p, n, n_flipped;
  e.deformed_positions(affine_dofs(m), p, exec);
  e.deformed_normals(s, p, n, exec);
  e.deformed_normals(flipped, p, n_flipped, exec);
  for (std::size_t v = 0; v < n.size(); ++v) EXPECT_EQ(n_flipped[v], Vec3(-n[v])) << v;
}

TEST(SurfaceEmbedding, FallbackVerticesBindToTheNearestLeafWithClampedWeights) {
  // Leaves exactly cover [2, 14] mm; the triangle's vertices lie outside all of them.
  const ObjectModel m = test::box_model({Vec3::Constant(0.002), Vec3::Constant(0.014)}, kRoot.min, kRoot.size, 3);
  const std::vector<Vec3> rest{Vec3(0.0145, 0.008, 0.0091),  // 0.5 mm beyond a face, on a leaf boundary in y
                               Vec3(0.0159, 0.0158, 0.0157),  // far beyond a corner: the weights must be clamped
                               Vec3(0.010, 0.009, 0.011)};    // inside
  const TriMesh s{rest, {{0, 1, 2}}};
  const SurfaceEmbedding e(m, s);
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
  const SurfaceEmbedding e(m, TriMesh{pts, {}});
  EXPECT_GT(e.num_fallback(), 1000);
  for (std::size_t v = 0; v < pts.size(); ++v)
    EXPECT_EQ(e.embeddings()[v], embed_vertex(m.tree(), m.root(), pts[v])) << "point " << v;
}

// ---- The fallback rule respects material components (SPEC §2.4) ----------------------------------------------------

// A closed axis-aligned box [lo, hi] (m) with n quads along EVERY edge whatever its length (unlike
// sim::closed_box_grid, whose cells are about square), welded, counter-clockwise seen from outside. The fallback tests
// count vertices per face with this layout.
TriMesh box_surface(const Vec3& lo, const Vec3& hi, int n) {
  TriMesh m;
  std::vector<int> id(std::size_t((n + 1) * (n + 1) * (n + 1)), -1);
  auto at = [&](int i, int j, int k) -> int& { return id[std::size_t((k * (n + 1) + j) * (n + 1) + i)]; };
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        if (i != 0 && i != n && j != 0 && j != n && k != 0 && k != n) continue;
        at(i, j, k) = int(m.vertices.size());
        // Exact lo and hi on the faces, so that tests can find a face's vertices by equality.
        const int idx[3] = {i, j, k};
        Vec3 p;
        for (int d = 0; d < 3; ++d)
          p[d] = idx[d] == 0 ? lo[d] : idx[d] == n ? hi[d] : lo[d] + (hi[d] - lo[d]) * idx[d] / n;
        m.vertices.push_back(p);
      }
  // Face with normal axis a on side s: (u, v) run along axes a + 1 and a + 2, whose cross product is +e_a.
  for (int a = 0; a < 3; ++a)
    for (const int side : {0, n})
      for (int u = 0; u < n; ++u)
        for (int v = 0; v < n; ++v) {
          auto corner = [&](int du, int dv) {
            int c[3];
            c[a] = side;
            c[(a + 1) % 3] = u + du;
            c[(a + 2) % 3] = v + dv;
            return int32_t(at(c[0], c[1], c[2]));
          };
          const int32_t p00 = corner(0, 0), p10 = corner(1, 0), p11 = corner(1, 1), p01 = corner(0, 1);
          if (side == n) {
            m.triangles.push_back({p00, p10, p11});
            m.triangles.push_back({p00, p11, p01});
          } else {
            m.triangles.push_back({p00, p11, p10});
            m.triangles.push_back({p00, p01, p11});
          }
        }
  return m;
}

// Appends mesh b to a, renumbering b's vertices.
void append(TriMesh& a, const TriMesh& b) {
  const int32_t off = int32_t(a.vertices.size());
  a.vertices.insert(a.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (const auto& t : b.triangles) a.triangles.push_back({t[0] + off, t[1] + off, t[2] + off});
}

// Two blocks of material, x in [2, 7] mm and [8, 14] mm (y, z in [2, 14] mm), 1 mm leaves aligned with the blocks:
// an empty 1 mm gap, no shared node, so two material components. A leaf is in the left block exactly when its box
// ends at x <= 7 mm: the independent truth the component tests check against.
constexpr double kGapMid = 0.0075;  // m
ObjectModel two_blocks_model() {
  OctreeSpec spec;
  spec.root = kRoot;
  spec.base_level = 4;
  spec.max_level = 6;
  return ObjectModel::build(spec,
                            std::make_shared<BoxSetMaterial>(
                                std::vector<Box3>{{Vec3(0.002, 0.002, 0.002), Vec3(0.007, 0.014, 0.014)},
                                                  {Vec3(0.008, 0.002, 0.002), Vec3(0.014, 0.014, 0.014)}}),
                            {}, {});
}
bool in_left_block(const ObjectModel& m, int leaf) { return m.root().cell_box(m.tree().leaf(leaf)).max.x() <= 0.007; }

// The left surface box reaches into the gap up to x = 7.8 mm, 0.8 mm from the left block and 0.2 mm from the right
// one; its vertices at x <= 7 mm lie in leaves, the last two columns (x = 7.27, 7.8 mm) in none. The right surface
// box sticks out of the material at y = 1.5 mm (fallback vertices whose nearest leaf is in their own block anyway).
const Vec3 kLeftLo(0.0025, 0.0025, 0.0025), kLeftHi(0.0078, 0.0135, 0.0135);
const Vec3 kRightLo(0.0085, 0.0015, 0.0025), kRightHi(0.0135, 0.0135, 0.0135);
constexpr int kBoxQuads = 10;

// The leaf nearest to p among those that pass `keep`, by a scan; the lowest index among equals.
template <class Keep>
int brute_nearest(const ObjectModel& m, const Vec3& p, Keep keep) {
  double best = std::numeric_limits<double>::infinity();
  int leaf = -1;
  for (int l = 0; l < m.num_elements(); ++l) {
    if (!keep(l)) continue;
    const Box3 b = m.root().cell_box(m.tree().leaf(l));
    const double d = (b.min - p).cwiseMax(p - b.max).cwiseMax(0.0).squaredNorm();
    if (d < best) best = d, leaf = l;
  }
  return leaf;
}

TEST(SurfaceEmbedding, FallbackVerticesStayInTheMaterialComponentOfTheirSurface) {
  const ObjectModel m = two_blocks_model();
  const TriMesh left = box_surface(kLeftLo, kLeftHi, kBoxQuads), right = box_surface(kRightLo, kRightHi, kBoxQuads);
  ASSERT_GT(signed_volume(left), 0.0);
  TriMesh s = left;
  append(s, right);
  const int n_left = int(left.vertices.size());
  const SurfaceEmbedding e(m, s);

  // The left box's face in the gap: nearer to the right block, yet bound to the nearest leaf of the left block.
  int gap_face = 0, right_fallback = 0;
  for (int v = 0; v < e.num_vertices(); ++v) {
    const Vec3& p = s.vertices[std::size_t(v)];
    const VertexEmbedding& ve = e.embeddings()[std::size_t(v)];
    const bool is_left = v < n_left;
    // Regular vertices lie in their own block; every vertex is bound to a leaf of its own block.
    EXPECT_EQ(in_left_block(m, ve.leaf), is_left) << "vertex " << v;
    if (!ve.fallback) continue;
    EXPECT_EQ(ve.leaf, brute_nearest(m, p, [&](int l) { return in_left_block(m, l) == is_left; })) << "vertex " << v;
    double sum = 0.0;
    for (const double w : ve.weights) {
      EXPECT_GE(w, kFallbackWeightMin);
      EXPECT_LE(w, kFallbackWeightMax);
      sum += w;
    }
    EXPECT_NEAR(sum, 1.0, 1e-14);
    if (is_left && p.x() == kLeftHi.x()) {
      // The old rule (plain nearest leaf, as embed_vertex still does) would take the right block here.
      ++gap_face;
      EXPECT_FALSE(in_left_block(m, embed_vertex(m.tree(), m.root(), p).leaf)) << "vertex " << v;
    }
    if (!is_left) ++right_fallback;
  }
  EXPECT_EQ(gap_face, (kBoxQuads + 1) * (kBoxQuads + 1));
  EXPECT_GT(right_fallback, 0);

  // Moving the right block's DOFs leaves the whole left surface where it was, and carries the right one along.
  std::vector<Vec3> x = m.dofs().dof_rest;
  const Vec3 shift(0.001, 0.002, -0.001);
  int moved = 0;
  for (Vec3& X : x)
    if (X.x() > kGapMid) X += shift, ++moved;
  ASSERT_GT(moved, 0);
  Executor one(1), two(2);
  std::vector<Vec3> rest_pos, p1, p2;
  e.deformed_positions(m.dofs().dof_rest, rest_pos, one);
  e.deformed_positions(x, p1, one);
  e.deformed_positions(x, p2, two);
  EXPECT_EQ(p1, p2);
  for (int v = 0; v < e.num_vertices(); ++v) {
    const Vec3 expected = rest_pos[std::size_t(v)] + (v < n_left ? Vec3::Zero() : shift);
    EXPECT_LT((p1[std::size_t(v)] - expected).norm(), 1e-15) << "vertex " << v;
  }
}

TEST(SurfaceEmbedding, SurfacePartsWithoutRegularVerticesUseThePlainNearestLeaf) {
  // The left surface box, and a small closed box floating above the gap (z = 14.2 .. 14.6 mm), nearer to the right
  // block (0.45 mm and more) than to the left one (0.55 mm and more), with no vertex in any leaf.
  const ObjectModel m = two_blocks_model();
  TriMesh s = box_surface(kLeftLo, kLeftHi, kBoxQuads);
  const int n_left = int(s.vertices.size());
  append(s, box_surface(Vec3(0.00755, 0.0076, 0.0142), Vec3(0.00795, 0.0084, 0.0146), 2));
  const SurfaceEmbedding e(m, s);
  int floating = 0;
  for (int v = n_left; v < e.num_vertices(); ++v) {
    const Vec3& p = s.vertices[std::size_t(v)];
    const VertexEmbedding& ve = e.embeddings()[std::size_t(v)];
    EXPECT_TRUE(ve.fallback);
    EXPECT_EQ(ve.leaf, brute_nearest(m, p, [](int) { return true; })) << "vertex " << v;
    EXPECT_FALSE(in_left_block(m, ve.leaf)) << "vertex " << v;
    EXPECT_EQ(ve, embed_vertex(m.tree(), m.root(), p)) << "vertex " << v;
    ++floating;
  }
  EXPECT_EQ(floating, 26);
  // The left box's gap face, close by, still follows the left block.
  for (int v = 0; v < n_left; ++v)
    if (s.vertices[std::size_t(v)].x() == kLeftHi.x()) {
      EXPECT_TRUE(in_left_block(m, e.embeddings()[std::size_t(v)].leaf));
    }
}

TEST(SurfaceEmbedding, FallbackAnchorIsTheNearestRegularVertexByEdgesThenByIndex) {
  // A strip across the gap: regular vertices a (left block) and b (right block), and the fallback chain f1 - f2 - f3
  // between them, each link a triangle closed by an extra vertex in the gap. f1 is 1 edge from a and 3 from b, f3
  // the reverse, f2 is 2 edges from both: it takes the one with the lower vertex index.
  const ObjectModel m = two_blocks_model();
  const Vec3 a(0.0065, 0.008, 0.008), b(0.0085, 0.008, 0.008);
  for (const bool a_first : {true, false}) {
    const int32_t ia = a_first ? 0 : 1, ib = a_first ? 1 : 0;
    std::vector<Vec3> rest{a_first ? a : b, a_first ? b : a};
    for (const double x : {0.0072, 0.0075, 0.0078}) rest.push_back(Vec3(x, 0.008, 0.008));      // f1, f2, f3
    for (const double x : {0.0071, 0.00735, 0.00765, 0.0079}) rest.push_back(Vec3(x, 0.008, 0.009));  // closers
    const SurfaceEmbedding e(m, TriMesh{rest, {{ia, 2, 5}, {2, 3, 6}, {3, 4, 7}, {4, ib, 8}}});
    EXPECT_EQ(e.num_fallback(), 7);
    const auto& emb = e.embeddings();
    EXPECT_TRUE(in_left_block(m, emb[std::size_t(ia)].leaf));
    EXPECT_FALSE(in_left_block(m, emb[std::size_t(ib)].leaf));
    EXPECT_TRUE(in_left_block(m, emb[2].leaf)) << "f1, a_first " << a_first;
    EXPECT_FALSE(in_left_block(m, emb[4].leaf)) << "f3, a_first " << a_first;
    EXPECT_EQ(in_left_block(m, emb[3].leaf), a_first) << "f2, a_first " << a_first;
    // Each is the nearest leaf of the block it follows.
    for (std::size_t v = 2; v < rest.size(); ++v) {
      const bool left = in_left_block(m, emb[v].leaf);
      EXPECT_EQ(emb[v].leaf, brute_nearest(m, rest[v], [&](int l) { return in_left_block(m, l) == left; }));
    }
  }
}

// A cut opens the gap: the model goes from one block, x in [2, 14] mm, to the two blocks (optionally refined at the
// gap's walls). The surface edit removes half of the left box's gap face and inserts `count` vertices in the gap,
// fanned together and tied to a kept vertex of the left box, so they take the left block's component although the
// right block is nearer.
void check_component_update_equals_rebuild(int count, bool refine, bool expect_merge) {
  const ObjectModel before = test::box_model({Vec3::Constant(0.002), Vec3::Constant(0.014)}, kRoot.min, kRoot.size, 4);
  ObjectModel after = two_blocks_model();
  TriMesh s = box_surface(kLeftLo, kLeftHi, kBoxQuads);
  const int n_left = int(s.vertices.size());
  append(s, box_surface(kRightLo, kRightHi, kBoxQuads));
  SurfaceEmbedding e(before, s);
  ASSERT_GT(e.num_fallback(), 0);

  SurfaceEdit edit;
  TriMesh cut;  // S after the edit
  std::vector<Vec3>& new_rest = cut.vertices;
  std::vector<int> map(s.vertices.size(), -1);
  int next = 0, tie = -1;
  for (int v = 0; v < int(s.vertices.size()); ++v) {
    const Vec3& p = s.vertices[std::size_t(v)];
    if (v < n_left && p.x() == kLeftHi.x() && p.y() < 0.008) {
      edit.removed_vertices.push_back(v);
    } else {
      map[std::size_t(v)] = next++;
      new_rest.push_back(p);
      if (v < n_left && p.x() < 0.007 && tie < 0) tie = map[std::size_t(v)];
    }
  }
  ASSERT_GE(tie, 0);
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> gx(0.0076, 0.0079), gyz(0.003, 0.0075);
  for (int i = 0; i < count; ++i) {
    const Vec3 p(gx(rng), gyz(rng), gyz(rng));
    ++edit.inserted;
    new_rest.push_back(p);
  }
  for (const auto& t : s.triangles)
    if (map[std::size_t(t[0])] >= 0 && map[std::size_t(t[1])] >= 0 && map[std::size_t(t[2])] >= 0)
      cut.triangles.push_back({map[std::size_t(t[0])], map[std::size_t(t[1])], map[std::size_t(t[2])]});
  for (int i = 0; i + 2 < count; ++i) cut.triangles.push_back({next + i, next + i + 1, next + i + 2});
  cut.triangles.push_back({tie, next, next + 1});
  if (refine) {
    // Refine the leaves on the gap's walls, and mark the new leaves there as changed.
    std::vector<int> pick;
    for (int l = 0; l < after.num_elements(); ++l) {
      const Box3 b = after.root().cell_box(after.tree().leaf(l));
      if (b.max.x() == 0.007 || b.min.x() == 0.008) pick.push_back(l);
    }
    after = after.refined(pick);
  }
  for (int l = 0; l < after.num_elements(); ++l) {
    const Box3 b = after.root().cell_box(after.tree().leaf(l));
    if (b.max.x() >= 0.0065 && b.min.x() <= 0.0085) edit.changed_leaves.push_back(l);
  }

  e.update(after, cut, edit);
  EXPECT_EQ(e.last_update_merged(), expect_merge);
  EXPECT_LT(e.last_reembedded(), e.num_vertices() / 2);
  const SurfaceEmbedding fresh(after, cut);
  expect_same(e, fresh);
  EXPECT_EQ(e.num_fallback(), fresh.num_fallback());

  // The component rule was at work: the inserted vertices are bound to the left block, where the plain nearest leaf
  // is in the right one; and the surface split by blocks holds everywhere.
  for (int v = 0; v < e.num_vertices(); ++v) {
    const VertexEmbedding& ve = e.embeddings()[std::size_t(v)];
    const bool is_left = v < n_left - int(edit.removed_vertices.size()) || v >= next;
    EXPECT_EQ(in_left_block(after, ve.leaf), is_left) << "vertex " << v;
    if (v >= next) {
      EXPECT_TRUE(ve.fallback);
      EXPECT_FALSE(in_left_block(after, embed_vertex(after.tree(), after.root(), new_rest[std::size_t(v)]).leaf));
    }
  }
}

// A hinted leaf that is kept must still give way when the cut puts it in another material component than the
// vertex's anchor. Two points above the right half of one block, tied by a triangle to a vertex of the left surface
// box, are bound to right-hand leaves while the block is whole; once the gap opens (the same 1 mm leaves, those of
// the gap gone) their anchor is in the left block, and so must their leaves be.
TEST(SurfaceEmbedding, UpdateMovesAFallbackVertexWhoseLeafLeftItsAnchorsComponent) {
  const ObjectModel before = test::box_model({Vec3::Constant(0.002), Vec3::Constant(0.014)}, kRoot.min, kRoot.size, 4);
  const ObjectModel after = two_blocks_model();
  TriMesh s = box_surface(kLeftLo, kLeftHi, kBoxQuads);
  int tie = -1;
  for (int v = 0; v < int(s.vertices.size()) && tie < 0; ++v)
    if (s.vertices[std::size_t(v)].x() < 0.006 && s.vertices[std::size_t(v)].z() == kLeftHi.z()) tie = v;
  ASSERT_GE(tie, 0);
  const auto f = int32_t(s.vertices.size());
  s.vertices.push_back(Vec3(0.0083, 0.008, 0.0143));
  s.vertices.push_back(Vec3(0.0086, 0.009, 0.0143));
  s.triangles.push_back({tie, f, f + 1});
  SurfaceEmbedding e(before, s);
  for (int k = 0; k < 2; ++k) {
    const VertexEmbedding& ve = e.embeddings()[std::size_t(f + k)];
    ASSERT_TRUE(ve.fallback);
    ASSERT_GE(before.root().cell_box(before.tree().leaf(ve.leaf)).min.x(), 0.008);
  }
  e.update(after, s, SurfaceEdit{});
  const SurfaceEmbedding fresh(after, s);
  expect_same(e, fresh);
  for (int k = 0; k < 2; ++k) EXPECT_TRUE(in_left_block(after, e.embeddings()[std::size_t(f + k)].leaf));
}

TEST(SurfaceEmbedding, ComponentFallbackUpdateOneByOneEqualsRebuild) {
  check_component_update_equals_rebuild(10, false, false);
}
TEST(SurfaceEmbedding, ComponentFallbackUpdateOneByOneWithRefinementEqualsRebuild) {
  check_component_update_equals_rebuild(10, true, false);
}
TEST(SurfaceEmbedding, ComponentFallbackUpdateMergeEqualsRebuild) {
  check_component_update_equals_rebuild(200, false, true);
}
TEST(SurfaceEmbedding, ComponentFallbackUpdateMergeWithRefinementEqualsRebuild) {
  check_component_update_equals_rebuild(200, true, true);
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
  std::vector<Vec3> inserted_rest;  ///< the new vertices, m
  TriMesh surface;                  ///< S after the cut
  ObjectModel new_model;
};

Cut make_cut(const ObjectModel& m, const TriMesh& s, int count, bool spread, bool refine) {
  const Vec3 spot = kCentre + Vec3(kRadii.x(), 0, 0);
  const double radius = 0.0015;
  Cut c{{}, {}, {}, m};
  std::vector<int> map(s.vertices.size(), -1);
  int next = 0;
  for (std::size_t v = 0; v < s.vertices.size(); ++v) {
    if ((s.vertices[v] - spot).norm() < radius)
      c.edit.removed_vertices.push_back(int(v));
    else
      map[v] = next++, c.surface.vertices.push_back(s.vertices[v]);
  }
  // Removed in descending order: any order must do.
  std::reverse(c.edit.removed_vertices.begin(), c.edit.removed_vertices.end());
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < count; ++i) {
    const Vec3 d(u(rng), u(rng), u(rng));
    const Vec3 p = spread ? Vec3(Vec3(0.008, 0.008, 0.008) + 0.0059 * d)
                          : Vec3(spot - Vec3(0.8 * radius, 0, 0) + 0.7 * radius * d);
    c.inserted_rest.push_back(p);
    c.surface.vertices.push_back(p);
  }
  c.edit.inserted = count;
  // Triangles among kept vertices survive, renumbered; a fan joins consecutive new vertices.
  for (const auto& t : s.triangles)
    if (map[std::size_t(t[0])] >= 0 && map[std::size_t(t[1])] >= 0 && map[std::size_t(t[2])] >= 0)
      c.surface.triangles.push_back({map[std::size_t(t[0])], map[std::size_t(t[1])], map[std::size_t(t[2])]});
  for (int i = 0; i + 2 < count; ++i) c.surface.triangles.push_back({next + i, next + i + 1, next + i + 2});
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
  SurfaceEmbedding e(m, s);
  ASSERT_EQ(e.num_fallback(), 2);
  const Cut cut = make_cut(m, s, count, spread, refine);
  ASSERT_GT(cut.edit.removed_vertices.size(), 5u);
  const std::vector<int> map = e.update(cut.new_model, cut.surface, cut.edit);
  EXPECT_EQ(e.last_update_merged(), expect_merge);
  // Only part of the surface was re-embedded.
  EXPECT_LT(e.last_reembedded(), e.num_vertices() / 2);
  EXPECT_GE(e.last_reembedded(), count);
  // The map sends kept vertices to their new slots.
  for (std::size_t v = 0; v < map.size(); ++v)
    if (map[v] >= 0) {
      EXPECT_EQ(cut.surface.vertices[std::size_t(map[v])], s.vertices[v]);
    }

  const SurfaceEmbedding fresh(cut.new_model, cut.surface);
  expect_same(e, fresh);
  EXPECT_EQ(e.num_fallback(), 2);
  Executor exec(2);
  std::vector<Vec3> pa, pb, na, nb;
  e.deformed_positions(affine_dofs(cut.new_model), pa, exec);
  fresh.deformed_positions(affine_dofs(cut.new_model), pb, exec);
  EXPECT_EQ(pa, pb);
  e.deformed_normals(cut.surface, pa, na, exec);
  fresh.deformed_normals(cut.surface, pb, nb, exec);
  EXPECT_EQ(na, nb);

  // The naive per-level lists, updated the same way, hold the same leaf sets as the Z-curve ranges.
  NaiveEmbedding naive(m.tree(), m.root(), s.vertices);
  EXPECT_EQ(naive.update(cut.edit.removed_vertices, cut.inserted_rest), map);
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

// update() keeps a kept fallback vertex's leaf without a search when its anchor is the same and no new leaf is as
// near, and runs in parallel when given an executor. Loose points scattered outside the material (no anchor: the
// plain nearest leaf), some next to the refined spot of the cut and most far from it, must be bound as a fresh
// embedding binds them, with one thread or two.
TEST(SurfaceEmbedding, UpdateOfScatteredFallbackVerticesEqualsRebuildWithAndWithoutThreads) {
  const ObjectModel m = hanging_model();
  TriMesh s = ellipsoid(kCentre, kRadii, 60, 30);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, kRoot.size);
  for (int loose = 0; loose < 300;) {
    const Vec3 p(u(rng), u(rng), u(rng));
    if (!embed_vertex(m.tree(), m.root(), p).fallback) continue;
    s.vertices.push_back(p);
    ++loose;
  }
  SurfaceEmbedding serial(m, s);
  SurfaceEmbedding parallel = serial;
  ASSERT_EQ(serial.num_fallback(), 300);
  const Cut cut = make_cut(m, s, 20, false, true);
  Executor two(2);
  serial.update(cut.new_model, cut.surface, cut.edit);
  parallel.update(cut.new_model, cut.surface, cut.edit, &two);
  const SurfaceEmbedding fresh(cut.new_model, cut.surface);
  expect_same(serial, fresh);
  expect_same(parallel, fresh);
  EXPECT_EQ(fresh.num_fallback(), serial.num_fallback());
  // One material component: every fallback vertex is on the leaf that the brute-force scan finds.
  for (int v = 0; v < fresh.num_vertices(); ++v) {
    const VertexEmbedding& ve = serial.embeddings()[std::size_t(v)];
    if (ve.fallback) {
      EXPECT_EQ(ve, embed_vertex(cut.new_model.tree(), cut.new_model.root(), cut.surface.vertices[std::size_t(v)]))
          << "vertex " << v;
    }
  }
}

// A hinted leaf that is kept must still give way to a new leaf that is nearer. The new revision here has material
// where the old had none (x from 8 to 14 mm; the old leaves are kept as they were): the loose points beyond
// x = 14 mm, bound before to the old leaves at x = 6..8 mm, now go to the new ones at x = 12..14 mm.
TEST(SurfaceEmbedding, UpdateMovesAFallbackVertexToANewLeafThatIsNearer) {
  const ObjectModel before =
      test::box_model({Vec3::Constant(0.002), Vec3(0.008, 0.014, 0.014)}, kRoot.min, kRoot.size, 3);
  const ObjectModel after = test::box_model({Vec3::Constant(0.002), Vec3::Constant(0.014)}, kRoot.min, kRoot.size, 3);
  TriMesh s = ellipsoid(Vec3(0.005, 0.008, 0.008), Vec3(0.002, 0.004, 0.004), 24, 12);
  for (int i = 0; i < 5; ++i) s.vertices.push_back(Vec3(0.015, 0.003 + 0.002 * i, 0.008));
  SurfaceEmbedding e(before, s);
  for (int i = 0; i < 5; ++i) {
    const VertexEmbedding& ve = e.embeddings()[s.vertices.size() - 5 + std::size_t(i)];
    ASSERT_TRUE(ve.fallback);
    EXPECT_LE(before.root().cell_box(before.tree().leaf(ve.leaf)).max.x(), 0.008);
  }
  e.update(after, s, SurfaceEdit{});
  const SurfaceEmbedding fresh(after, s);
  expect_same(e, fresh);
  for (int i = 0; i < 5; ++i) {
    const VertexEmbedding& ve = e.embeddings()[s.vertices.size() - 5 + std::size_t(i)];
    EXPECT_EQ(after.root().cell_box(after.tree().leaf(ve.leaf)).max.x(), 0.014);
  }
}

// Euclidean distance from p to the closed box b, m.
double box_distance(const Box3& b, const Vec3& p) { return (b.min - p).cwiseMax(p - b.max).cwiseMax(0.0).norm(); }

// update() keeps the rows it can in the current CSR and moves them in runs: down where rows before them went, up
// where rows before them grew (here the leaves around the first vertices are refined, so their rows gain the
// hanging nodes' DOFs, while vertices further on are removed). Two successive cuts of one S, followed by the
// embedding and by a copy of it, must each equal a fresh embedding.
TEST(SurfaceEmbedding, SuccessiveUpdatesOfAnEmbeddingAndOfItsCopyEqualRebuild) {
  const ObjectModel m = hanging_model();
  TriMesh s = ellipsoid(kCentre, kRadii, 48, 24);
  SurfaceEmbedding e(m, s), copy = e;
  ObjectModel model = m;
  for (int round = 0; round < 2; ++round) {
    // Refine the leaves that hold the first vertices (or, second round, those of a middle band).
    const Vec3 near = s.vertices[round == 0 ? 0 : s.vertices.size() / 2];
    std::vector<int> pick;
    for (int l = 0; l < model.num_elements(); ++l)
      if (box_distance(model.root().cell_box(model.tree().leaf(l)), near) < 0.0015) pick.push_back(l);
    ASSERT_FALSE(pick.empty());
    model = model.refined(pick);
    // Remove every 7th vertex of the last third, insert 5 new ones near the first vertex, joined by a fan.
    SurfaceEdit edit;
    std::vector<int> map(s.vertices.size(), -1);
    int next = 0;
    for (std::size_t v = 0; v < s.vertices.size(); ++v) {
      if (v > 2 * s.vertices.size() / 3 && v % 7 == 0)
        edit.removed_vertices.push_back(int(v));
      else
        map[v] = next++;
    }
    std::vector<Vec3> inserted;
    for (int i = 0; i < 5; ++i) inserted.push_back(near + Vec3(-0.0002 * i, 0.0001 * i, -0.0003));
    edit.inserted = 5;
    std::vector<std::array<int32_t, 3>> triangles;
    for (const auto& t : s.triangles)
      if (map[std::size_t(t[0])] >= 0 && map[std::size_t(t[1])] >= 0 && map[std::size_t(t[2])] >= 0)
        triangles.push_back({map[std::size_t(t[0])], map[std::size_t(t[1])], map[std::size_t(t[2])]});
    for (int i = 0; i + 2 < 5; ++i) triangles.push_back({next + i, next + i + 1, next + i + 2});
    for (int l = 0; l < model.num_elements(); ++l)
      if (box_distance(model.root().cell_box(model.tree().leaf(l)), near) < 0.0015) edit.changed_leaves.push_back(l);
    s = edited(s, edit.removed_vertices, inserted, std::move(triangles));

    EXPECT_EQ(e.update(model, s, edit), map);
    EXPECT_EQ(copy.update(model, s, edit), map);
    const SurfaceEmbedding fresh(model, s);
    expect_same(e, fresh);
    expect_same(copy, fresh);
    EXPECT_EQ(e.last_reembedded(), copy.last_reembedded());
    EXPECT_LT(e.last_reembedded(), e.num_vertices() / 2);
    Executor exec(1);
    std::vector<Vec3> pa, pb, na, nb;
    copy.deformed_positions(affine_dofs(model), pa, exec);
    fresh.deformed_positions(affine_dofs(model), pb, exec);
    EXPECT_EQ(pa, pb);
    copy.deformed_normals(s, pa, na, exec);
    fresh.deformed_normals(s, pb, nb, exec);
    EXPECT_EQ(na, nb);
  }
}

TEST(SurfaceEmbedding, RebindAfterRefinementEqualsRebuild) {
  const ObjectModel m = hanging_model();
  const TriMesh s = ellipsoid(kCentre, kRadii, 48, 24);
  SurfaceEmbedding e(m, s);
  const ObjectModel r = m.refined({0, 3, m.num_elements() / 2, m.num_elements() - 1});
  e.rebind(r, s);
  expect_same(e, SurfaceEmbedding(r, s));
  EXPECT_LT(e.last_reembedded(), e.num_vertices());
}

// Revisions from with_material (cutting stage 4). First a slit 2 um wide on the leaf face x = 7 mm: the same leaves,
// but the nodes on that face split, so the DOFs after them are renumbered and the leaves beside the slit get new
// rows of P. Then the slab y in [7, 9] mm of the left part goes: its leaves and the nodes inside it go too. Each
// update with the same surface must equal a fresh embedding, for the vertices whose rows it keeps (renumbered) and
// for those it composes anew.
TEST(SurfaceEmbedding, UpdateAfterWithMaterialEqualsRebuild) {
  OctreeSpec spec;
  spec.root = kRoot;
  spec.base_level = 4;
  spec.max_level = 6;
  const ObjectModel before = ObjectModel::build(
      spec, std::make_shared<BoxSetMaterial>(std::vector<Box3>{{Vec3(0.002, 0.002, 0.002), Vec3(0.014, 0.014, 0.014)}}),
      {}, {});
  const ObjectModel slit = before.with_material(
      std::make_shared<BoxSetMaterial>(std::vector<Box3>{{Vec3(0.002, 0.002, 0.002), Vec3(0.006999, 0.014, 0.014)},
                                                         {Vec3(0.007001, 0.002, 0.002), Vec3(0.014, 0.014, 0.014)}}),
      {{Vec3(0.0065, 0.0015, 0.0015), Vec3(0.0075, 0.0145, 0.0145)}});
  ASSERT_EQ(slit.tree().leaves(), before.tree().leaves());
  ASSERT_GT(slit.num_dofs(), before.num_dofs());
  const TriMesh s = ellipsoid(kCentre, kRadii, 60, 30);
  SurfaceEmbedding e(before, s);
  const SurfaceEdit edit;
  e.update(slit, s, edit);
  EXPECT_EQ(e.last_reembedded(), 0);
  expect_same(e, SurfaceEmbedding(slit, s));

  const ObjectModel gap = slit.with_material(
      std::make_shared<BoxSetMaterial>(std::vector<Box3>{{Vec3(0.002, 0.002, 0.002), Vec3(0.006999, 0.007, 0.014)},
                                                         {Vec3(0.002, 0.009, 0.002), Vec3(0.006999, 0.014, 0.014)},
                                                         {Vec3(0.007001, 0.002, 0.002), Vec3(0.014, 0.014, 0.014)}}),
      {{Vec3(0.0015, 0.0065, 0.0015), Vec3(0.0075, 0.0095, 0.0145)}});
  ASSERT_LT(gap.num_elements(), slit.num_elements());
  ASSERT_LT(gap.num_dofs(), slit.num_dofs());
  e.update(gap, s, edit);
  EXPECT_LT(e.last_reembedded(), e.num_vertices() / 2);
  const SurfaceEmbedding fresh(gap, s);
  expect_same(e, fresh);
  EXPECT_GT(fresh.num_fallback(), 0);
}

TEST(SurfaceEmbedding, ThreadCountDoesNotChangeResults) {
  const ObjectModel m = hanging_model();
  const TriMesh s = ellipsoid(kCentre, kRadii, 160, 80);  // ~12.6k vertices: several parallel chunks
  const SurfaceEmbedding e(m, s);
  // A smooth non-affine field on the DOFs.
  std::vector<Vec3> x;
  for (const Vec3& X : m.dofs().dof_rest)
    x.push_back(X + 0.001 * Vec3(std::sin(400 * X.y()), std::cos(300 * X.z()), std::sin(500 * X.x())));
  Executor one(1), two(2);
  std::vector<Vec3> p1, p2, n1, n2;
  e.deformed_positions(x, p1, one);
  e.deformed_positions(x, p2, two);
  EXPECT_EQ(p1, p2);
  e.deformed_normals(s, p1, n1, one);
  e.deformed_normals(s, p2, n2, two);
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
  EXPECT_NE(message([&] { SurfaceEmbedding(m, TriMesh{s.vertices, bad_tris}); }).find("triangle 3 corner 1"),
            std::string::npos);
  auto bad_pts = s.vertices;
  bad_pts[5].y() = std::nan("");
  EXPECT_NE(message([&] { SurfaceEmbedding(m, TriMesh{bad_pts, s.triangles}); }).find("vertex 5"), std::string::npos);

  // A failed update leaves the embedding as it was.
  SurfaceEmbedding e(m, s);
  const auto before = e.zcurve().entries();
  SurfaceEdit edit;
  edit.removed_vertices = {4, 7, 4};
  const TriMesh no_triangles{s.vertices, {}};
  EXPECT_NE(message([&] { e.update(m, no_triangles, edit); }).find("removed_vertices[2] = 4 is listed twice"),
            std::string::npos);
  edit.removed_vertices = {4};
  const TriMesh bad_corner = edited(s, {4}, {}, {{0, 1, int32_t(s.vertices.size() - 1)}});
  EXPECT_NE(message([&] { e.update(m, bad_corner, edit); }).find("triangle 0 corner 2"), std::string::npos);
  // S must already be the edited surface: one vertex fewer here.
  EXPECT_NE(message([&] { e.update(m, s, edit); }).find("the surface has"), std::string::npos);
  EXPECT_EQ(e.zcurve().entries(), before);
  // The calls that read S check that it is the surface the embedding is built for.
  std::vector<Vec3> n, rest = s.vertices;
  Executor one(1);
  EXPECT_NE(message([&] { e.deformed_normals(bad_corner, rest, n, one); }).find("the surface has"),
            std::string::npos);
  EXPECT_NE(message([&] { e.rebind(m, bad_corner); }).find("the surface has"), std::string::npos);
  std::vector<Vec3> p;
  Executor exec(1);
  EXPECT_NE(message([&] { e.deformed_positions({Vec3::Zero()}, p, exec); }).find("DOF positions"), std::string::npos);
}

}  // namespace
}  // namespace octocut::sim
