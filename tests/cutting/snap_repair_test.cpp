// Near-coincident walls snap together (snap_target) and the rounded boolean is repaired instead of rejected
// (repair_rounding, through cut_surface). Independent truth: the geometry of the configurations (the Hausdorff
// distance of two prisms moved apart by d is d), an own watertightness check and CGAL's exact self-intersection test
// of the whole result (tests/cutting/watertight.hpp), and volumes recomputed from the meshes (divergence theorem).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include "octocut/cutting/blade.hpp"
#include "octocut/cutting/mesh_check.hpp"
#include "octocut/cutting/surface_cut.hpp"
#include "octocut/sim/primitives.hpp"
#include "octocut/sim/surface.hpp"
#include "../common/shapes.hpp"
#include "watertight.hpp"

namespace octocut::cutting {
namespace {

using sim::TriMesh;
using sim::Vec3;

constexpr double kRadius = 1e-3;     // the punch, m
constexpr double kFeature = 3e-4;    // min_feature, m
const Vec3 kAxis(0.0101, 0.0103, 0.002);  // the punch's centre, m

TriMesh punch(const Vec3& shift, double height = 0.02) { return test::prism_mesh(kAxis + shift, kRadius, height, 32); }

// The punch turned by `angle` (rad) about the x axis through its centre, then moved by `shift`.
TriMesh tilted(double angle, const Vec3& shift) {
  TriMesh m = punch(Vec3::Zero());
  const double c = std::cos(angle), s = std::sin(angle);
  for (Vec3& p : m.vertices) {
    const Vec3 q = p - kAxis;
    p = kAxis + shift + Vec3(q.x(), c * q.y() - s * q.z(), s * q.y() + c * q.z());
  }
  return m;
}

// Where the material is: the 2 x 2 x 0.4 cm slab's box, grown by min_feature.
const sim::Box3 kRegion{Vec3::Constant(-kFeature), Vec3(0.02, 0.02, 0.004) + Vec3::Constant(kFeature)};

TEST(SnapTarget, ABladeWithinMinFeatureOfAnEarlierOneSnapsToIt) {
  const std::vector<TriMesh> earlier{punch(Vec3(0.005, 0.0, 0.0)), punch(Vec3::Zero())};
  for (const double d : {1e-9, 3e-5, 2.9e-4}) {
    double distance = 0.0;
    EXPECT_EQ(snap_target(punch(d * Vec3(0.6, 0.8, 0.0)), earlier, kRegion, kFeature, &distance), 1) << d;
    // The Hausdorff distance of a 32-gon prism and its copy moved sideways by d: between d cos(pi / 32) and d.
    EXPECT_LE(distance, d * (1.0 + 1e-9)) << d;
    EXPECT_GE(distance, d * std::cos(M_PI / 32.0) * (1.0 - 1e-9)) << d;
  }
  // Sliding along its own axis by 5 mm moves no wall inside the slab: it snaps (its caps are far outside).
  double distance = 1.0;
  EXPECT_EQ(snap_target(punch(Vec3(0.0, 0.0, 0.005)), earlier, kRegion, kFeature, &distance), 1);
  EXPECT_LT(distance, 1e-12);
  // Tilted by 1 degree: the walls move by up to (2 mm + 0.3 mm) tan(1 deg) = 40 um inside the grown slab.
  EXPECT_EQ(snap_target(tilted(M_PI / 180.0, Vec3::Zero()), earlier, kRegion, kFeature, &distance), 1);
  EXPECT_NEAR(distance, 2.3e-3 * std::tan(M_PI / 180.0), 2e-6);
}

// A blade whose sides are cut into many triangles per face (a finely tessellated instrument: 40 bands, 2,624
// triangles) is the same solid as the plain punch: it snaps, and is measured, exactly as the plain one does.
TEST(SnapTarget, ABladeWithManyTrianglesPerFaceSnapsAsTheSameSolidWithFew) {
  const auto ringed = [](const Vec3& shift) { return test::ringed_prism_mesh(kAxis + shift, kRadius, 0.02, 32, 40); };
  const std::vector<TriMesh> earlier_plain{punch(Vec3(0.005, 0.0, 0.0)), punch(Vec3::Zero())};
  const std::vector<TriMesh> earlier_ringed{ringed(Vec3(0.005, 0.0, 0.0)), ringed(Vec3::Zero())};
  for (const double d : {1e-9, 3e-5, 2.9e-4, 3.1e-4, 1e-3}) {
    const Vec3 shift = d * Vec3(0.6, 0.8, 0.0);
    double plain = -1.0, fine = -1.0;
    const int k = snap_target(punch(shift), earlier_plain, kRegion, kFeature, &plain);
    EXPECT_EQ(snap_target(ringed(shift), earlier_ringed, kRegion, kFeature, &fine), k) << d;
    EXPECT_EQ(k, d < kFeature ? 1 : -1) << d;
    if (k < 0) continue;
    // The Hausdorff distance of the prism and its copy moved sideways by d, as for the plain punch.
    EXPECT_NEAR(fine, plain, 1e-12 * kRadius) << d;
    EXPECT_LE(fine, d * (1.0 + 1e-9)) << d;
    EXPECT_GE(fine, d * std::cos(M_PI / 32.0) * (1.0 - 1e-9)) << d;
  }
}

TEST(SnapTarget, ABladeFartherThanMinFeatureOrOfAnotherMeshDoesNotSnap) {
  const std::vector<TriMesh> earlier{punch(Vec3::Zero())};
  EXPECT_EQ(snap_target(punch(Vec3(3.1e-4, 0.0, 0.0)), earlier, kRegion, kFeature), -1);
  EXPECT_EQ(snap_target(tilted(10.0 * M_PI / 180.0, Vec3::Zero()), earlier, kRegion, kFeature), -1);
  // A punch ending 0.5 mm deeper inside the slab (a bite): its floor moved by more than min_feature.
  const std::vector<TriMesh> bite{punch(Vec3(0.0, 0.0, 0.0015), 0.002)};
  EXPECT_EQ(snap_target(punch(Vec3(0.0, 0.0, 0.001), 0.002), bite, kRegion, kFeature), -1);
  EXPECT_EQ(snap_target(punch(Vec3(0.0, 0.0, 0.0014), 0.002), bite, kRegion, kFeature), 0);
  // Another mesh (24 sides), a blade in the air, min_feature off: never.
  EXPECT_EQ(snap_target(test::prism_mesh(kAxis, kRadius, 0.02, 24), earlier, kRegion, kFeature), -1);
  EXPECT_EQ(snap_target(punch(Vec3(0.0, 0.0, 0.05)), {punch(Vec3(0.0, 0.0, 0.0501))}, kRegion, kFeature), -1);
  EXPECT_EQ(snap_target(punch(Vec3::Zero()), earlier, kRegion, 0.0), -1);
}

// A non-convex blade: an L-shaped prism (arms 4 mm long and 1 mm thick, 2 cm tall) with its corner at kAxis, moved
// by `shift` and then turned by `angle` (rad) about the x axis through kAxis + shift.
TriMesh l_prism(const Vec3& shift, double angle = 0.0) {
  constexpr double a = 4e-3, t = 1e-3, h = 0.02;  // m
  const std::array<std::array<double, 2>, 6> outline{{{0, 0}, {a, 0}, {a, t}, {t, t}, {t, a}, {0, a}}};
  TriMesh m;
  for (const double z : {-0.5 * h, 0.5 * h})
    for (const auto& q : outline) m.vertices.emplace_back(q[0], q[1], z);
  const int n = 6;
  for (const auto& f : std::array<std::array<int, 3>, 4>{{{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 4, 5}}}) {
    m.triangles.push_back({f[0], f[2], f[1]});          // bottom, facing -z
    m.triangles.push_back({f[0] + n, f[1] + n, f[2] + n});  // top
  }
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    m.triangles.push_back({i, j, j + n});
    m.triangles.push_back({i, j + n, i + n});
  }
  const double c = std::cos(angle), s = std::sin(angle);
  for (Vec3& p : m.vertices) p = kAxis + shift + Vec3(p.x(), c * p.y() - s * p.z(), s * p.y() + c * p.z());
  return m;
}

// A blade that is not convex snaps by its vertices' correspondence (the same mesh mapped differently): the Hausdorff
// distance of the two solids inside the region is at most the largest move of a point of the blade whose path meets
// the region. A translate by d is at distance d (every point moves by d); a turn about an axis through the slab
// moves the far ends of the 2 cm blade by more than min_feature but the walls inside the slab by less.
TEST(SnapTarget, ANonConvexBladeSnapsWhereItsWallsMoveLessThanMinFeatureInsideTheRegion) {
  ASSERT_GT(sim::signed_volume(l_prism(Vec3::Zero())), 0.0);
  const std::vector<TriMesh> earlier{l_prism(Vec3(0.005, 0.0, 0.0)), l_prism(Vec3::Zero())};
  for (const double d : {1e-9, 3e-5, 2.9e-4, 3.1e-4}) {
    double distance = -1.0;
    EXPECT_EQ(snap_target(l_prism(d * Vec3(0.6, 0.0, 0.8)), earlier, kRegion, kFeature, &distance),
              d < kFeature ? 1 : -1) << d;
    if (d >= kFeature) continue;
    // d, up to the rounding of the vertices' differences (coordinates of 1e-2 m) and the bound's own margin.
    EXPECT_GE(distance, d * (1.0 - 1e-9)) << d;
    EXPECT_LE(distance, d * (1.0 + 1e-9) + 1e-15) << d;
  }
  // Turned by 3 degrees about x: the blade's ends (1 cm from the axis) move by 2 (1 cm) sin(1.5 deg) = 0.52 mm.
  const double angle = 3.0 * M_PI / 180.0;
  double distance = -1.0;
  EXPECT_EQ(snap_target(l_prism(Vec3::Zero(), angle), earlier, kRegion, kFeature, &distance), 1);
  EXPECT_LE(distance, kFeature);
  // At least the move of the arm's tip where the blade leaves the grown slab (2.3 mm above kAxis, 4 mm along y).
  EXPECT_GE(distance, 2.0 * std::hypot(4e-3, 2.3e-3) * std::sin(0.5 * angle));
  // Turned by 6 degrees: the walls inside the slab move by more than min_feature.
  EXPECT_EQ(snap_target(l_prism(Vec3::Zero(), 2.0 * angle), earlier, kRegion, kFeature), -1);
  // Another mesh never snaps.
  EXPECT_EQ(snap_target(l_prism(Vec3::Zero()), {punch(Vec3::Zero())}, kRegion, kFeature), -1);
}

// The bound is a bound: two L prisms whose vertices moved independently (not an affine map) by up to 0.25 mm, and
// points on a grid around them in the region: every point inside one solid and outside the other lies within the
// reported distance of the other's surface.
TEST(SnapTarget, TheNonConvexBoundHoldsForIndependentVertexMoves) {
  const TriMesh a = l_prism(Vec3::Zero());
  for (int seed = 1; seed <= 3; ++seed) {
    TriMesh b = a;
    for (std::size_t v = 0; v < b.vertices.size(); ++v) {
      const double u = double(seed * 7919 + int(v) * 104729 % 1000) / 1000.0;  // deterministic, in [0, 1)
      b.vertices[v] += 2.5e-4 * Vec3(std::sin(13.0 * u + seed), std::cos(7.0 * u), std::sin(5.0 * u - seed)) / 1.8;
    }
    double bound = -1.0;
    if (snap_target(b, {a}, kRegion, 1e-3, &bound) != 0) ADD_FAILURE() << "no snap at seed " << seed;
    const BladeVolume va(a), vb(b);
    // The grid: around the L (x, y from -0.6 to 4.6 mm of its corner) through the region's depth.
    const Vec3 lo(kAxis.x() - 6e-4, kAxis.y() - 6e-4, kRegion.min.z());
    const Vec3 hi(kAxis.x() + 4.6e-3, kAxis.y() + 4.6e-3, kRegion.max.z());
    int differing = 0;
    for (int i = 0; i <= 60; ++i)
      for (int j = 0; j <= 60; ++j)
        for (int k = 0; k <= 20; ++k) {
          const Vec3 p = lo + Vec3(i / 60.0, j / 60.0, k / 20.0).cwiseProduct(hi - lo);
          const bool in_a = va.contains(p), in_b = vb.contains(p);
          if (in_a == in_b) continue;
          ++differing;
          EXPECT_LE((in_a ? vb : va).distance(p), bound * (1.0 + 1e-9)) << seed << " at " << p.transpose();
        }
    EXPECT_GT(differing, 0) << seed;  // the grid sees the two solids differ
  }
}

// Blind holes in the slab, each bite 0.4 mm deeper and its walls a hair off the last one's (turned by ~1e-12 rad and
// moved by ~1e-12 m, as the rest-space maps of a deformed object give): the walls meet at rounding distances, and the
// exact result rounded to doubles has degenerate or intersecting triangles unless it is repaired.
TEST(RoundingRepair, NearCoincidentBitesAreRepairedNotRejected) {
  TriMesh s = sim::closed_box_grid({Vec3::Zero(), Vec3(0.02, 0.02, 0.004)}, 8);
  const double v0 = sim::signed_volume(s);
  SurfaceCutOptions plain;
  plain.verify = false;  // neither repair nor verification: the rounded result as it is
  int defects_without = 0, collapses = 0;
  double removed = 0.0;  // m^3
  for (int bite = 0; bite < 8; ++bite) {
    const double e = 1e-12 * (1 + bite % 3);
    // A 4 mm punch standing 2 mm above the slab, its floor 0.4 mm deeper each bite.
    TriMesh blade = test::prism_mesh(Vec3::Zero(), kRadius, 0.004, 32);
    const double c = std::cos(e), sn = std::sin(bite % 2 == 0 ? e : -e);
    for (Vec3& p : blade.vertices) {
      p = Vec3(p.x(), c * p.y() - sn * p.z(), sn * p.y() + c * p.z()) +
          Vec3(0.0101 + 0.37 * e, 0.0103 - 0.21 * e, 0.006 - 0.0004 * (bite + 1) - 0.0);
    }
    const SurfaceCutResult raw = cut_surface(s, blade, plain);
    if (raw.status == SurfaceCutStatus::ok) {
      bool bad = false;
      for (const auto& t : raw.mesh.triangles) {
        const Vec3& a = raw.mesh.vertices[std::size_t(t[0])];
        const Vec3& b = raw.mesh.vertices[std::size_t(t[1])];
        const Vec3& c3 = raw.mesh.vertices[std::size_t(t[2])];
        bad = bad || t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || !((b - a).cross(c3 - a).norm() > 0.0);
      }
      if (!bad) bad = find_self_intersection(raw.mesh).has_value();
      defects_without += bad ? 1 : 0;
    }
    const SurfaceCutResult r = cut_surface(s, blade);
    ASSERT_EQ(r.status, SurfaceCutStatus::ok) << bite << ": " << r.reason;
    collapses += r.collapses;
    test::expect_watertight(r.mesh, "bite " + std::to_string(bite));
    EXPECT_NEAR(sim::signed_volume(s) - sim::signed_volume(r.mesh), r.removed_volume, 1e-12 * v0);
    removed += r.removed_volume;
    s = r.mesh;
  }
  // The configuration is a hard one: rounded as it is, some results are broken (5 of the 8 bites here), and the
  // repair mended them by collapses.
  EXPECT_GT(defects_without, 0);
  EXPECT_GT(collapses, 0);
  // The hole: the 32-gon prism from z = 0.8 mm up through the top face (3.2 mm), up to the rounding of the walls.
  EXPECT_NEAR(removed, test::prism_area(kRadius, 32) * 0.0032, 1e-9 * test::prism_area(kRadius, 32) * 0.0032);
  EXPECT_NEAR(sim::signed_volume(s), v0 - removed, 1e-12 * v0);
}

// Punches through the slab whose walls pierce its top and bottom faces 1 um from a vertex of S: the exact result has
// edges of about 1 um there. With a collapse length of 3 um (SurfaceCutOptions::tiny_edge; the pipeline's 0.01
// min_feature) they collapse, the result stays watertight, and the removed volume moves from the exact prism's by
// less than the collapse length times the area that moved (the walls and the faces of S around them).
TEST(RoundingRepair, EdgesShorterThanTheCollapseLengthCollapseAndTheVolumeMovesByLessThanItTimesTheArea) {
  constexpr double kTiny = 3e-6;   // m
  constexpr double kSlab = 0.004;  // m, thickness
  const TriMesh s = sim::closed_box_grid({Vec3::Zero(), Vec3(0.02, 0.02, kSlab)}, 8);  // 2.5 mm cells
  const double exact = test::prism_area(kRadius, 32) * kSlab;  // m^3, one hole
  int cases = 0;
  for (const Vec3& g : {Vec3(0.005, 0.005, 0.0), Vec3(0.0125, 0.0075, 0.0), Vec3(0.0075, 0.015, 0.0)}) {
    for (const double angle : {0.3, 1.9, 4.1}) {
      // The prism's vertex at angle 0 (a vertical edge of the blade) 1 um from the grid vertex g.
      const Vec3 c = g + Vec3(-kRadius + 1e-6 * std::cos(angle), 1e-6 * std::sin(angle), 0.5 * kSlab);
      const TriMesh blade = test::prism_mesh(c, kRadius, 2.0 * kSlab, 32);
      SurfaceCutOptions exact_cut, collapsing;
      collapsing.tiny_edge = kTiny;
      const SurfaceCutResult r0 = cut_surface(s, blade, exact_cut);
      const SurfaceCutResult r1 = cut_surface(s, blade, collapsing);
      ASSERT_EQ(r0.status, SurfaceCutStatus::ok) << r0.reason;
      ASSERT_EQ(r1.status, SurfaceCutStatus::ok) << r1.reason;
      const std::string where = "grid vertex " + std::to_string(g.x()) + ", " + std::to_string(g.y()) + ", angle " +
                                std::to_string(angle);
      // The exact cut has the short edges and removes the prism; the collapsing one has none left.
      EXPECT_LT(r0.min_edge, kTiny) << where;
      EXPECT_NEAR(r0.removed_volume, exact, 1e-9 * exact) << where;
      EXPECT_GT(r1.collapses, 0) << where;
      EXPECT_GE(r1.min_edge, kTiny) << where;
      test::expect_watertight(r1.mesh, where);
      EXPECT_NEAR(sim::signed_volume(s) - sim::signed_volume(r1.mesh), r1.removed_volume, 1e-12 * sim::signed_volume(s));
      // What moved: the hole's wall and the faces of S around it (top and bottom, within a cell of the hole).
      const double moved_area = 2.0 * M_PI * kRadius * kSlab + 2.0 * std::pow(2.0 * kRadius + 0.005, 2);  // m^2
      EXPECT_LE(std::abs(r1.removed_volume - exact), kTiny * moved_area) << where;
      ++cases;
    }
  }
  EXPECT_EQ(cases, 9);
}

// The smallest interior angle (degrees) among the triangles of `after` that are not triangles of `before` (compared by
// their corners' coordinates), recomputed from the meshes.
double smallest_new_angle_deg(const TriMesh& before, const TriMesh& after) {
  using Key = std::array<double, 9>;
  const auto key = [](const TriMesh& m, const std::array<int32_t, 3>& t) {
    std::array<std::array<double, 3>, 3> c;
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = m.vertices[static_cast<std::size_t>(t[k])];
      c[k] = {p.x(), p.y(), p.z()};
    }
    std::sort(c.begin(), c.end());
    Key out;
    for (int k = 0; k < 9; ++k) out[k] = c[k / 3][k % 3];
    return out;
  };
  std::set<Key> old;
  for (const auto& t : before.triangles) old.insert(key(before, t));
  double smallest = 180.0;
  for (const auto& t : after.triangles) {
    if (old.count(key(after, t)) != 0) continue;
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = after.vertices[static_cast<std::size_t>(t[k])];
      const Vec3 u = after.vertices[static_cast<std::size_t>(t[(k + 1) % 3])] - p;
      const Vec3 v = after.vertices[static_cast<std::size_t>(t[(k + 2) % 3])] - p;
      smallest = std::min(smallest, std::atan2(u.cross(v).norm(), u.dot(v)) * 180.0 / M_PI);
    }
  }
  return smallest;
}

// A second bite exactly below the first (the same punch, its floor 0.5 or 2 min_feature deeper: a repeated punch of a
// tissue at rest): its walls lie exactly on the first bite's. The exact result rounded to doubles has clusters of
// nodes ulps apart, sliver bubbles and caps (a corner within 1e-19 m of the opposite edge); before the repair learned
// clusters, bubbles and narrow pieces, the 0.5 case was refused ("no collapse mends it") and the 2.0 case kept caps of
// 2e-13 degrees. Now both cut without moving the blade, watertight, remove the prism band between the two floors to
// 1e-9, and keep no new angle under 0.05 degrees.
TEST(RoundingRepair, ABiteExactlyBelowTheLastCutsCleanlyWithoutMovingTheBlade) {
  const TriMesh s0 = sim::closed_box_grid({Vec3::Zero(), Vec3(0.02, 0.02, 0.004)}, 8);
  SurfaceCutOptions options;
  options.tiny_edge = 0.01 * kFeature;  // the pipeline's collapse length
  // The first bite: its floor 1.5 mm below the top face.
  const SurfaceCutResult first = cut_surface(s0, punch(Vec3(0.0, 0.0, 0.0105)), options);
  ASSERT_EQ(first.status, SurfaceCutStatus::ok) << first.reason;
  for (const double deeper : {0.5, 2.0}) {
    const std::string where = "deeper by " + std::to_string(deeper) + " min_feature";
    const SurfaceCutResult r = cut_surface(first.mesh, punch(Vec3(0.0, 0.0, 0.0105 - deeper * kFeature)), options);
    ASSERT_EQ(r.status, SurfaceCutStatus::ok) << where << ": " << r.reason;
    test::expect_watertight(r.mesh, where);
    const double band = test::prism_area(kRadius, 32) * deeper * kFeature;  // m^3
    EXPECT_NEAR(r.removed_volume, band, 1e-9 * band) << where;
    EXPECT_NEAR(sim::signed_volume(first.mesh) - sim::signed_volume(r.mesh), r.removed_volume,
                1e-12 * sim::signed_volume(s0)) << where;
    EXPECT_GE(smallest_new_angle_deg(first.mesh, r.mesh), 0.05) << where;
  }
}

// Fourteen bites of a 3 mm 16-gon punch into the 1 cm cube (S a 24 x 24 grid per face), each 0.35 mm deeper than the
// last, as a rigid tissue under a punch driven deeper at one spot gives them (the stability study's punch at E = 1e9
// Pa): every bite's walls lie on the last one's, and vertices of S that an earlier rounding left a hair off the new
// walls' edges make caps. Through cut_surface_perturbing (the pipeline's cut): every bite cuts, the result stays
// watertight, the volumes add up, and no new angle is under 0.01 degrees (before the repair flipped caps and
// collapsed narrow pieces: 9e-14 to 2e-6 degrees in 13 of the 14 bites).
TEST(RoundingRepair, RepeatedDeeperBitesOfARigidCubeLeaveNoCaps) {
  TriMesh s = sim::closed_box_grid({Vec3::Zero(), Vec3::Constant(0.01)}, 24);
  const double v0 = sim::signed_volume(s);
  SurfaceCutOptions options;
  options.tiny_edge = 0.01 * kFeature;
  double removed = 0.0, floor = 0.01;  // m^3; m
  std::size_t first_size = 0;
  for (int bite = 1; bite <= 14; ++bite) {
    floor = 0.01 - 0.00035 * bite;
    TriMesh blade = test::prism_mesh(Vec3(0.005, 0.005, floor + 0.005), 0.0015, 0.01, 16);
    const SurfaceCutResult r = cut_surface_perturbing(s, blade, options).first;
    const std::string where = "bite " + std::to_string(bite);
    ASSERT_EQ(r.status, SurfaceCutStatus::ok) << where << ": " << r.reason;
    test::expect_watertight(r.mesh, where);
    EXPECT_NEAR(sim::signed_volume(s) - sim::signed_volume(r.mesh), r.removed_volume, 1e-12 * v0) << where;
    EXPECT_GE(smallest_new_angle_deg(s, r.mesh), 0.01) << where;
    removed += r.removed_volume;
    s = r.mesh;
    if (bite == 1) first_size = s.vertices.size();
  }
  // The hole: the prism down to the last floor, up to the collapse length times the area that moved (walls, floor).
  const double prism = test::prism_area(0.0015, 16) * (0.01 - floor);
  const double moved_area = 2.0 * M_PI * 0.0015 * (0.01 - floor) + 2.0 * test::prism_area(0.0015, 16);
  EXPECT_NEAR(removed, prism, options.tiny_edge * moved_area);
  // S stays bounded. CGAL's triangulation of the coplanar walls, and with it the count, depends on the allocation
  // history of the process (this test alone, after the other RoundingRepair tests, or after all of this binary's:
  // 1.09-1.52x), so the bound is 2x, not the 1.5x for 100 punches (which the slab scenes check).
  EXPECT_LE(s.vertices.size(), 2.0 * static_cast<double>(first_size));
}

}  // namespace
}  // namespace octocut::cutting
