// The local surface boolean S \ B' (SPEC §4 stage 2): outcomes, coplanar and touching configurations, analytic
// volumes, vertex bookkeeping and watertightness, each checked independently of the implementation (own edge and fan
// counting, CGAL self-intersection test, analytic volumes).
#include "octocut/cutting/surface_cut.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <set>
#include <string>
#include <utility>

#include "octocut/cutting/mesh_check.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/sim/surface.hpp"
#include "../common/shapes.hpp"
#include "test_meshes.hpp"
#include "watertight.hpp"

namespace octocut::cutting {
namespace {

using test::expect_watertight;

using sim::TriMesh;
using sim::Vec3;

// The closed box [lo, hi], 12 triangles, outward oriented.
TriMesh box(const Vec3& lo, const Vec3& hi) {
  TriMesh m = test::grid_cube(1, 1.0);
  for (Vec3& p : m.vertices) p = lo + (hi - lo).cwiseProduct(p);
  return m;
}

// A closed prism around the z axis through (cx, cy): a regular n-gon of circumradius r from z0 to z1 (test::prism_mesh).
// Volume = polygon area * (z1 - z0).
TriMesh cylinder(double cx, double cy, double r, double z0, double z1, int n = 32) {
  return test::prism_mesh(Vec3(cx, cy, 0.5 * (z0 + z1)), r, z1 - z0, n);
}

using test::prism_area;  // the area of the regular n-gon of circumradius r, m^2

// Bookkeeping: kept vertices unchanged and in order, inserted == tail, origins in range and coplanar with the old
// triangle, removed volume equal to the volume difference.
void expect_bookkeeping(const TriMesh& s, const SurfaceCutResult& r, const std::string& what) {
  ASSERT_TRUE(std::is_sorted(r.removed_vertices.begin(), r.removed_vertices.end())) << what;
  std::vector<Vec3> kept;
  std::size_t j = 0;
  for (int v = 0; v < static_cast<int>(s.vertices.size()); ++v) {
    if (j < r.removed_vertices.size() && r.removed_vertices[j] == v) {
      ++j;
      continue;
    }
    kept.push_back(s.vertices[static_cast<std::size_t>(v)]);
  }
  ASSERT_EQ(j, r.removed_vertices.size()) << what << ": removed index out of range";
  ASSERT_EQ(kept.size() + r.inserted_vertices.size(), r.mesh.vertices.size()) << what;
  for (std::size_t k = 0; k < kept.size(); ++k) ASSERT_EQ(kept[k], r.mesh.vertices[k]) << what << ": kept " << k;
  for (std::size_t k = 0; k < r.inserted_vertices.size(); ++k) {
    ASSERT_EQ(r.inserted_vertices[k], r.mesh.vertices[kept.size() + k]) << what << ": inserted " << k;
  }
  ASSERT_EQ(r.triangle_origin.size(), r.mesh.triangles.size()) << what;
  const double scale = (sim::bounds(s).max - sim::bounds(s).min).norm();
  for (std::size_t f = 0; f < r.mesh.triangles.size(); ++f) {
    const int32_t o = r.triangle_origin[f];
    if (o < 0) continue;
    ASSERT_LT(o, static_cast<int32_t>(s.triangles.size())) << what;
    const auto& t = s.triangles[static_cast<std::size_t>(o)];
    const Vec3 a = s.vertices[static_cast<std::size_t>(t[0])];
    const Vec3 n = (s.vertices[static_cast<std::size_t>(t[1])] - a).cross(s.vertices[static_cast<std::size_t>(t[2])] - a).normalized();
    for (const int32_t v : r.mesh.triangles[f]) {
      ASSERT_LT(std::abs(n.dot(r.mesh.vertices[static_cast<std::size_t>(v)] - a)), 1e-9 * scale)
          << what << ": triangle " << f << " leaves the plane of its origin " << o;
    }
  }
  const auto blade_faces = std::count(r.triangle_origin.begin(), r.triangle_origin.end(), -1);
  EXPECT_EQ(blade_faces, r.blade_triangles_kept) << what;
  const double before = sim::signed_volume(s), after = sim::signed_volume(r.mesh);
  EXPECT_NEAR(r.removed_volume, before - after, 1e-10 * std::abs(before) + 1e-13 * scale * scale * scale) << what;
}

// A successful cut: status ok, bookkeeping, watertight.
void expect_valid_cut(const TriMesh& s, const SurfaceCutResult& r, const std::string& what) {
  ASSERT_EQ(r.status, SurfaceCutStatus::ok) << what << ": " << r.reason;
  expect_bookkeeping(s, r, what);
  if (!r.mesh.triangles.empty()) expect_watertight(r.mesh, what);
}

TEST(SurfaceCut, CavityWhenTheBladeIsInside) {
  const TriMesh s = test::grid_cube(4, 1.0);
  const TriMesh b = box(Vec3(0.3, 0.35, 0.4), Vec3(0.6, 0.7, 0.65));
  const SurfaceCutResult r = cut_surface(s, b);
  expect_valid_cut(s, r, "cavity");
  EXPECT_NEAR(r.removed_volume, 0.3 * 0.35 * 0.25, 1e-14);
  EXPECT_NEAR(sim::signed_volume(r.mesh), 1.0 - 0.3 * 0.35 * 0.25, 1e-14);
  EXPECT_TRUE(r.removed_vertices.empty());
  EXPECT_EQ(r.inserted_vertices.size(), 8u);
  EXPECT_EQ(r.mesh.triangles.size(), s.triangles.size() + 12);
}

TEST(SurfaceCut, CavityFarFromEveryFace) {
  // The blade's box meets no face's box: the patch is empty and the point-in-surface test decides.
  const TriMesh s = test::cube_sphere(8, 1.0);
  const TriMesh b = test::octahedron(0.2);
  const SurfaceCutResult r = cut_surface(s, b);
  expect_valid_cut(s, r, "far cavity");
  EXPECT_EQ(r.patch_triangles, 0);
  EXPECT_NEAR(r.removed_volume, 4.0 / 3.0 * 0.008, 1e-14);
}

TEST(SurfaceCut, MissIsNoOp) {
  const TriMesh s = test::grid_cube(4, 1.0);
  for (const TriMesh& b : {box(Vec3(2, 2, 2), Vec3(3, 3, 3)), box(Vec3(0.9, 0.9, 1.2), Vec3(1.5, 1.5, 1.5))}) {
    const SurfaceCutResult r = cut_surface(s, b);
    EXPECT_EQ(r.status, SurfaceCutStatus::no_op) << r.reason;
    EXPECT_EQ(r.mesh.vertices, s.vertices);
    EXPECT_EQ(r.mesh.triangles, s.triangles);
    EXPECT_TRUE(r.removed_vertices.empty());
    EXPECT_TRUE(r.inserted_vertices.empty());
  }
}

TEST(SurfaceCut, BladeContainingTheObjectRemovesEverything) {
  const TriMesh s = test::grid_cube(3, 1.0);
  const SurfaceCutResult r = cut_surface(s, box(Vec3(-1, -0.5, -2), Vec3(2, 1.5, 1.25)));
  ASSERT_EQ(r.status, SurfaceCutStatus::ok) << r.reason;
  EXPECT_TRUE(r.mesh.triangles.empty());
  EXPECT_TRUE(r.mesh.vertices.empty());
  EXPECT_EQ(r.removed_vertices.size(), s.vertices.size());
  EXPECT_NEAR(r.removed_volume, 1.0, 1e-14);
}

TEST(SurfaceCut, FacesStrictlyInsideTheBladeGoWithoutCorefinement) {
  // A finely tessellated cube (32 x 32 quads a side) loses a 0.6 x 0.6 x 0.1 slab from its top. About 740 top faces
  // lie strictly inside the blade: they go whole, and only the faces along the contour are corefined.
  const TriMesh s = test::grid_cube(32, 1.0);
  const SurfaceCutResult r = cut_surface(s, box(Vec3(0.2, 0.2, 0.9), Vec3(0.8, 0.8, 1.5)));
  expect_valid_cut(s, r, "slab");
  EXPECT_NEAR(r.removed_volume, 0.6 * 0.6 * 0.1, 1e-14);
  EXPECT_EQ(test::euler_characteristic(r.mesh), 2);
  EXPECT_LT(r.patch_triangles, 400);
  const auto kept_top = std::count_if(r.mesh.triangles.begin(), r.mesh.triangles.end(), [&](const auto& t) {
    return r.mesh.vertices[std::size_t(t[0])].z() == 1.0 && r.mesh.vertices[std::size_t(t[1])].z() == 1.0 &&
           r.mesh.vertices[std::size_t(t[2])].z() == 1.0;
  });
  double top_area = 0.0;  // what is left of the top face
  for (const auto& t : r.mesh.triangles) {
    const Vec3& a = r.mesh.vertices[std::size_t(t[0])];
    const Vec3& b = r.mesh.vertices[std::size_t(t[1])];
    const Vec3& c = r.mesh.vertices[std::size_t(t[2])];
    if (a.z() == 1.0 && b.z() == 1.0 && c.z() == 1.0) top_area += 0.5 * (b - a).cross(c - a).norm();
  }
  EXPECT_GT(kept_top, 0);
  EXPECT_NEAR(top_area, 1.0 - 0.36, 1e-12);
}

TEST(SurfaceCut, SliverFacesAcrossTheBladeAreCut) {
  // The unit cube's top face with a vertex 1e-12 off its diagonal: the triangle it splits becomes a sliver (aspect
  // about 1e12) along the diagonal, crossed by the walls of a box blade punched 0.1 deep, all tilted. The sliver must
  // be found to touch the blade and be cut exactly.
  TriMesh s = test::grid_cube(1, 1.0);
  const Vec3 m(0.5, 0.5 + 1e-12, 1.0);
  const auto v = static_cast<int32_t>(s.vertices.size());
  s.vertices.push_back(m);
  bool split = false;
  for (std::size_t f = 0; f < s.triangles.size() && !split; ++f) {
    const auto t = s.triangles[f];
    const Vec3& p = s.vertices[std::size_t(t[0])];
    const Vec3& q = s.vertices[std::size_t(t[1])];
    const Vec3& r = s.vertices[std::size_t(t[2])];
    if (p.z() != 1.0 || q.z() != 1.0 || r.z() != 1.0) continue;
    // m inside (p, q, r) in xy: the same side of all three edges.
    const auto side = [&](const Vec3& a, const Vec3& b) {
      return (b.x() - a.x()) * (m.y() - a.y()) - (b.y() - a.y()) * (m.x() - a.x());
    };
    if (!(side(p, q) > 0 && side(q, r) > 0 && side(r, p) > 0)) continue;
    s.triangles[f] = {t[0], t[1], v};
    s.triangles.push_back({t[1], t[2], v});
    s.triangles.push_back({t[2], t[0], v});
    split = true;
  }
  ASSERT_TRUE(split);
  // Tilted, so that the planes' normals are rounded.
  TriMesh b = box(Vec3(0.4, 0.4, 0.9), Vec3(0.6, 0.6, 1.1));
  const Eigen::Matrix3d rot = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  for (Vec3& p : s.vertices) p = rot * p;
  for (Vec3& p : b.vertices) p = rot * p;
  expect_watertight(s, "input");
  const SurfaceCutResult r = cut_surface(s, b);
  // (expect_bookkeeping's plane test of each piece against its origin cannot take such a sliver's rounded normal.)
  ASSERT_EQ(r.status, SurfaceCutStatus::ok) << r.reason;
  expect_watertight(r.mesh, "sliver");
  EXPECT_NEAR(r.removed_volume, 0.2 * 0.2 * 0.1, 1e-14);
  EXPECT_NEAR(sim::signed_volume(s) - sim::signed_volume(r.mesh), r.removed_volume, 1e-14);
  EXPECT_FALSE(find_self_intersection(r.mesh).has_value());
}

TEST(SurfaceCut, ComponentInsideTheBladeGoesWholeWhileAnotherIsCut) {
  // A small cube entirely inside the blade goes whole (no face of it touches the blade), while the big one beside
  // it loses the part the blade covers.
  TriMesh small = test::grid_cube(4, 0.2);
  for (Vec3& p : small.vertices) p += Vec3(1.4, 0.4, 0.4);
  const TriMesh s = test::merged(test::grid_cube(4, 1.0), small);
  const SurfaceCutResult r = cut_surface(s, box(Vec3(0.75, 0.25, 0.25), Vec3(1.75, 0.75, 0.75)));
  expect_valid_cut(s, r, "beside");
  EXPECT_NEAR(r.removed_volume, 0.25 * 0.5 * 0.5 + 0.2 * 0.2 * 0.2, 1e-14);
  for (const Vec3& p : r.mesh.vertices) EXPECT_LE(p.x(), 1.0);
  EXPECT_EQ(test::euler_characteristic(r.mesh), 2);
}

TEST(SurfaceCut, CoplanarFlushInsideOnVertices) {
  // The blade's top face lies in the surface's top plane and its corners on surface vertices.
  const TriMesh s = test::grid_cube(4, 1.0);
  const SurfaceCutResult r = cut_surface(s, box(Vec3(0.25, 0.25, 0.5), Vec3(0.75, 0.75, 1.0)));
  expect_valid_cut(s, r, "flush on vertices");
  EXPECT_NEAR(r.removed_volume, 0.125, 1e-14);
}

TEST(SurfaceCut, CoplanarFlushInsideOnEdges) {
  // Corners on surface edges (x = 0.3, 0.7 cross the grid lines y = 0.25, 0.75) and in faces (z = 0.55).
  const TriMesh s = test::grid_cube(4, 1.0);
  const SurfaceCutResult r = cut_surface(s, box(Vec3(0.3, 0.25, 0.55), Vec3(0.7, 0.75, 1.0)));
  expect_valid_cut(s, r, "flush on edges");
  EXPECT_NEAR(r.removed_volume, 0.4 * 0.5 * 0.45, 1e-14);
}

TEST(SurfaceCut, CoplanarWithFourFacesRemovesASlab) {
  // The blade shares the planes x = 1, y = 0, y = 1 and z = 1 with the surface and sticks out through none.
  const TriMesh s = test::grid_cube(4, 1.0);
  const SurfaceCutResult r = cut_surface(s, box(Vec3(0.5, 0.0, 0.5), Vec3(1.0, 1.0, 1.0)));
  expect_valid_cut(s, r, "slab");
  EXPECT_NEAR(r.removed_volume, 0.25, 1e-14);
}

TEST(SurfaceCut, CornerBladeStickingOut) {
  const TriMesh s = test::grid_cube(4, 1.0);
  const SurfaceCutResult r = cut_surface(s, box(Vec3(0.6, 0.7, 0.55), Vec3(1.5, 1.25, 1.2)));
  expect_valid_cut(s, r, "corner");
  EXPECT_NEAR(r.removed_volume, 0.4 * 0.3 * 0.45, 1e-14);
  EXPECT_FALSE(r.removed_vertices.empty());
}

TEST(SurfaceCut, CoplanarTouchingFromOutsideIsNoOp) {
  const TriMesh s = test::grid_cube(4, 1.0);
  for (const TriMesh& b : {box(Vec3(0.25, 0.25, 1.0), Vec3(0.75, 0.75, 1.5)),   // on vertices
                           box(Vec3(0.3, 0.2, 1.0), Vec3(0.7, 0.6, 1.5)),       // inside faces and across edges
                           box(Vec3(0.5, 0.3, 1.0), Vec3(1.5, 0.6, 1.5))}) {    // over the rim of the face
    const SurfaceCutResult r = cut_surface(s, b);
    EXPECT_EQ(r.status, SurfaceCutStatus::no_op) << r.reason;
    EXPECT_EQ(r.mesh.triangles, s.triangles);
  }
}

TEST(SurfaceCut, OctahedronWithVerticesOnSurfaceVertices) {
  // Equatorial vertices on grid vertices of the top face, one apex inside: half an octahedron goes.
  const TriMesh s = test::grid_cube(4, 1.0);
  TriMesh b = test::octahedron(0.25);
  for (Vec3& p : b.vertices) p += Vec3(0.5, 0.5, 1.0);
  const SurfaceCutResult r = cut_surface(s, b);
  expect_valid_cut(s, r, "octahedron");
  EXPECT_NEAR(r.removed_volume, 2.0 / 3.0 * 0.25 * 0.25 * 0.25, 1e-14);
}

TEST(SurfaceCut, CylinderPunchThroughABoxHasTheAnalyticVolume) {
  // A 2 mm punch through a 10 mm box, and one that stops 3 mm above the bottom.
  const double e = 0.01, r = 0.001;
  const TriMesh s = test::grid_cube(8, e);
  const SurfaceCutResult through = cut_surface(s, cylinder(0.0053, 0.0047, r, -0.002, 0.012));
  expect_valid_cut(s, through, "through");
  EXPECT_NEAR(through.removed_volume, prism_area(r, 32) * e, 1e-9 * e * e * e);
  const SurfaceCutResult partial = cut_surface(s, cylinder(0.0053, 0.0047, r, 0.003, 0.012));
  expect_valid_cut(s, partial, "partial");
  EXPECT_NEAR(partial.removed_volume, prism_area(r, 32) * (e - 0.003), 1e-9 * e * e * e);
  EXPECT_GT(partial.patch_triangles, 0);
  EXPECT_LT(partial.patch_triangles, static_cast<int>(s.triangles.size()) / 10);
}

TEST(SurfaceCut, FiftyPunchesAtOneSpotStayValid) {
  const double e = 0.01, r = 0.001;
  TriMesh s = test::grid_cube(8, e);
  const TriMesh b = cylinder(0.0041, 0.0063, r, 0.004, 0.012, 24);
  const double v0 = sim::signed_volume(s);
  int ok = 0;
  for (int i = 0; i < 50; ++i) {
    const SurfaceCutResult c = cut_surface(s, b);
    ASSERT_NE(c.status, SurfaceCutStatus::failed) << "punch " << i << ": " << c.reason;
    if (c.status == SurfaceCutStatus::ok) {
      expect_valid_cut(s, c, "punch " + std::to_string(i));
      if (i > 0) {
        EXPECT_LT(std::abs(c.removed_volume), 1e-6 * e * e * e) << "punch " << i;
      }
      s = c.mesh;
      ++ok;
    }
  }
  EXPECT_GE(ok, 1);
  EXPECT_NEAR(v0 - sim::signed_volume(s), prism_area(r, 24) * (e - 0.004), 1e-9 * e * e * e);
}

TEST(SurfaceCut, SixPunchesAtDifferentSpots) {
  const double e = 0.01, r = 0.0008;
  TriMesh s = test::grid_cube(6, e);
  const double v0 = sim::signed_volume(s);
  double expected = 0.0;
  for (int i = 0; i < 6; ++i) {
    const double x = 0.0015 + 0.0014 * i, y = 0.002 + 0.001 * i, depth = 0.002 + 0.001 * i;
    const SurfaceCutResult c = cut_surface(s, cylinder(x, y, r, e - depth, e + 0.002, 20));
    expect_valid_cut(s, c, "punch " + std::to_string(i));
    expected += prism_area(r, 20) * depth;
    s = c.mesh;
  }
  EXPECT_NEAR(v0 - sim::signed_volume(s), expected, 1e-9 * e * e * e);
}

TEST(SurfaceCut, TiltedPunchesThroughASphereAreDeterministic) {
  // Cylinders at oblique angles through a sphere mesh: no plane or vertex lines up with the axes.
  TriMesh s = test::cube_sphere(12, 0.01);
  for (int i = 0; i < 4; ++i) {
    TriMesh b = cylinder(0.0, 0.0, 0.0015, -0.004, 0.02, 28);
    const Eigen::Matrix3d rot =
        (Eigen::AngleAxisd(0.3 + 0.7 * i, Vec3::UnitZ()) * Eigen::AngleAxisd(0.4 + 0.25 * i, Vec3::UnitX()))
            .toRotationMatrix();
    for (Vec3& p : b.vertices) p = rot * p + Vec3(0.001 * i, -0.0005 * i, 0.0002);
    const SurfaceCutResult r = cut_surface(s, b);
    expect_valid_cut(s, r, "tilted " + std::to_string(i));
    const SurfaceCutResult again = cut_surface(s, b);
    EXPECT_EQ(again.mesh.vertices, r.mesh.vertices);
    EXPECT_EQ(again.mesh.triangles, r.mesh.triangles);
    EXPECT_EQ(again.triangle_origin, r.triangle_origin);
    SurfaceCutOptions unchecked;
    unchecked.verify = false;
    EXPECT_EQ(cut_surface(s, b, unchecked).mesh.triangles, r.mesh.triangles);
    s = r.mesh;
  }
}

TEST(SurfaceCut, RandomBladeSequenceStaysWatertight) {
  // 24 boxes and prisms at pseudo-random positions and angles (fixed seed), cut one after the other from a sphere.
  TriMesh s = test::cube_sphere(10, 0.01);
  uint64_t state = 12345;
  const auto uniform = [&]() {  // in [0, 1)
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) * 0x1.0p-53;
  };
  int ok = 0;
  for (int i = 0; i < 24; ++i) {
    TriMesh b = i % 2 == 0 ? cylinder(0.0, 0.0, 0.0005 + 0.0015 * uniform(), -0.003, 0.003 + 0.01 * uniform(), 12 + i)
                           : box(Vec3(-0.002, -0.001, -0.0015), Vec3(0.002 * uniform() + 0.0005, 0.001, 0.004));
    const Eigen::Matrix3d rot = (Eigen::AngleAxisd(6.283 * uniform(), Vec3::UnitZ()) *
                                 Eigen::AngleAxisd(3.1416 * uniform(), Vec3::UnitX()))
                                    .toRotationMatrix();
    const Vec3 at = 0.012 * Vec3(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5);
    for (Vec3& p : b.vertices) p = rot * p + at;
    const SurfaceCutResult r = cut_surface(s, b);
    ASSERT_NE(r.status, SurfaceCutStatus::failed) << "blade " << i << ": " << r.reason;
    if (r.status == SurfaceCutStatus::no_op) continue;
    expect_valid_cut(s, r, "blade " + std::to_string(i));
    s = r.mesh;
    ++ok;
  }
  EXPECT_GE(ok, 12);
}

TEST(SurfaceCut, GridAlignedBoxesRemoveTheirExactIntersectionWithTheCube) {
  // 300 boxes with corners on the eighths of [-1/4, 5/4], some subdivided into 2-4 cells per side (their vertices
  // at thirds then round), cut from the unit cube meshed at quarters: faces coplanar with the cube's, edges along its
  // edges, vertices on its vertices, and intersection points a few ulps apart. The removed volume is that of the
  // box's intersection with the cube; a degenerate position that the boolean cannot round is moved by 1e-9 (or
  // 1e-7, 1e-5) of the blade's size, which changes the volume by less than 1e-6 (1e-4 for the last).
  const TriMesh s = test::grid_cube(4, 1.0);
  uint64_t state = 777;
  const auto next = [&](int n) {  // in [0, n)
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<int>((state >> 33) % static_cast<uint64_t>(n));
  };
  int ok = 0, no_op = 0, moved = 0;
  for (int i = 0; i < 300; ++i) {
    Vec3 lo, hi;
    for (int k = 0; k < 3; ++k) {
      const int a = next(13) - 2;
      int b = next(13) - 2;
      if (a == b) b = a + 1;
      lo[k] = std::min(a, b) / 8.0;
      hi[k] = std::max(a, b) / 8.0;
    }
    TriMesh b = i % 3 == 2 ? test::grid_cube(2 + next(3), 1.0) : box(Vec3::Zero(), Vec3::Ones());
    for (Vec3& p : b.vertices) p = lo + (hi - lo).cwiseProduct(p);
    double expected = 1.0;  // m^3
    for (int k = 0; k < 3; ++k) expected *= std::max(0.0, std::min(hi[k], 1.0) - std::max(lo[k], 0.0));
    const std::string what = "box " + std::to_string(i);
    auto [r, moves] = cut_surface_perturbing(s, b);
    ASSERT_NE(r.status, SurfaceCutStatus::failed) << what << ": " << r.reason;
    moved += moves > 0 ? 1 : 0;
    if (r.status == SurfaceCutStatus::no_op) {
      EXPECT_LT(expected, 1e-6) << what;
      ++no_op;
      continue;
    }
    expect_valid_cut(s, r, what);
    EXPECT_NEAR(r.removed_volume, expected, moves > 2 ? 1e-4 : moves > 0 ? 1e-6 : 1e-12) << what;
    ++ok;
  }
  EXPECT_GE(ok, 150);
  EXPECT_GE(no_op, 30);
  EXPECT_LE(moved, 10);
}

TEST(SurfaceCut, BadInputFails) {
  const TriMesh s = test::grid_cube(2, 1.0);
  TriMesh b = box(Vec3(0.2, 0.2, 0.2), Vec3(0.6, 0.6, 1.4));
  TriMesh nan_blade = b;
  nan_blade.vertices[3].y() = std::numeric_limits<double>::quiet_NaN();
  SurfaceCutResult r = cut_surface(s, nan_blade);
  EXPECT_EQ(r.status, SurfaceCutStatus::failed);
  EXPECT_NE(r.reason.find("blade vertex 3"), std::string::npos) << r.reason;

  TriMesh bad_index = s;
  bad_index.triangles[5][1] = 1000;
  r = cut_surface(bad_index, b);
  EXPECT_EQ(r.status, SurfaceCutStatus::failed);
  EXPECT_NE(r.reason.find("surface triangle 5"), std::string::npos) << r.reason;

  TriMesh open = b;
  open.triangles.pop_back();
  r = cut_surface(s, open);
  EXPECT_EQ(r.status, SurfaceCutStatus::failed);
  EXPECT_NE(r.reason.find("not closed"), std::string::npos) << r.reason;

  TriMesh inverted = b;
  for (auto& t : inverted.triangles) std::swap(t[1], t[2]);
  r = cut_surface(s, inverted);
  EXPECT_EQ(r.status, SurfaceCutStatus::failed);
  EXPECT_NE(r.reason.find("outward"), std::string::npos) << r.reason;

  r = cut_surface(s, test::merged(b, box(Vec3(0.4, 0.4, 0.4), Vec3(0.8, 0.8, 0.8))));
  EXPECT_EQ(r.status, SurfaceCutStatus::failed);
  EXPECT_NE(r.reason.find("intersects itself"), std::string::npos) << r.reason;
  EXPECT_TRUE(r.mesh.triangles.empty());

  // A self-intersecting surface near the blade (the faces x = 1 and y = 0.5 cross inside and beside it): CGAL's
  // exception or the verification turns it into a failure.
  const TriMesh overlapping = test::merged(s, box(Vec3(0.5, 0.5, 0.5), Vec3(1.5, 1.5, 1.5)));
  r = cut_surface(overlapping, box(Vec3(0.95, 0.45, 0.6), Vec3(1.05, 0.55, 0.7)));
  EXPECT_EQ(r.status, SurfaceCutStatus::failed);
  EXPECT_NE(r.reason.find("ntersect"), std::string::npos) << r.reason;  // "Self-intersection ..." or "... intersect"
}

TEST(SurfaceCut, SurfaceCheckOffGivesTheSameResult) {
  // Skipping CGAL's self-intersection check of S (for a surface known to be valid) changes nothing in the result.
  const double e = 0.01, r = 0.001;
  const TriMesh s = test::grid_cube(8, e);
  const TriMesh b = cylinder(0.0053, 0.0047, r, 0.003, 0.012);
  SurfaceCutOptions unchecked;
  unchecked.check_surface_self_intersection = false;
  const SurfaceCutResult a = cut_surface(s, b);
  const SurfaceCutResult c = cut_surface(s, b, unchecked);
  expect_valid_cut(s, c, "unchecked");
  EXPECT_EQ(a.mesh.vertices, c.mesh.vertices);
  EXPECT_EQ(a.mesh.triangles, c.mesh.triangles);
  EXPECT_EQ(a.triangle_origin, c.triangle_origin);
  EXPECT_EQ(a.removed_volume, c.removed_volume);
}

TEST(SurfaceCut, RemovableRestrictsTheCutToWhereItSaysYes) {
  // Two 10 mm cubes stacked with a 2 mm gap, one punch through both. Restricted to z < 11 mm, only the lower cube
  // gets a hole; the upper one stays exactly as it was (split along the blade's contour at most, same volume).
  // The grids are fine enough (0.625 mm) for faces to lie strictly inside the 1 mm blade.
  const double e = 0.01, r = 0.001;
  TriMesh upper = test::grid_cube(16, e);
  for (Vec3& p : upper.vertices) p.z() += 0.012;
  const TriMesh s = test::merged(test::grid_cube(16, e), upper);
  const TriMesh b = cylinder(0.0053, 0.0047, r, -0.002, 0.025);
  const SurfaceCutResult both = cut_surface(s, b);
  expect_valid_cut(s, both, "both");
  EXPECT_NEAR(both.removed_volume, 2.0 * prism_area(r, 32) * e, 1e-9 * e * e * e);

  SurfaceCutOptions lower_only;
  lower_only.removable = [](const Vec3& p) { return p.z() < 0.011; };
  const SurfaceCutResult lower = cut_surface(s, b, lower_only);
  expect_valid_cut(s, lower, "lower only");
  EXPECT_NEAR(lower.removed_volume, prism_area(r, 32) * e, 1e-9 * e * e * e);
  EXPECT_NEAR(sim::signed_volume(lower.mesh), sim::signed_volume(s) - lower.removed_volume, 1e-15);
  // No blade face (cut face) lies in the upper cube, and the upper cube keeps its volume: the vertices above
  // z = 11 mm bound the same solid.
  for (std::size_t f = 0; f < lower.mesh.triangles.size(); ++f) {
    if (lower.triangle_origin[f] >= 0) continue;
    for (const int32_t v : lower.mesh.triangles[f]) EXPECT_LT(lower.mesh.vertices[std::size_t(v)].z(), 0.011);
  }
  TriMesh top;
  std::map<int32_t, int32_t> index;
  for (const auto& t : lower.mesh.triangles) {
    if (lower.mesh.vertices[std::size_t(t[0])].z() < 0.011) continue;
    std::array<int32_t, 3> u{};
    for (int k = 0; k < 3; ++k) {
      const auto [it, added] = index.emplace(t[std::size_t(k)], int32_t(top.vertices.size()));
      if (added) top.vertices.push_back(lower.mesh.vertices[std::size_t(t[std::size_t(k)])]);
      u[std::size_t(k)] = it->second;
    }
    top.triangles.push_back(u);
  }
  EXPECT_NEAR(sim::signed_volume(top), e * e * e, 1e-15);
  expect_watertight(top, "upper cube");

  // Nowhere: nothing changes.
  SurfaceCutOptions nowhere;
  nowhere.removable = [](const Vec3&) { return false; };
  EXPECT_EQ(cut_surface(s, b, nowhere).status, SurfaceCutStatus::no_op);
}

// The 10k meniscus in metres (file in mm).
const TriMesh& meniscus() {
  static const TriMesh m = [] {
    engine::MeshLoadOptions o;
    o.scale = 0.001;
    o.self_intersections = false;
    return engine::load_mesh(std::string(OCTOCUT_SOURCE_DIR) + "/assets/meshes/meniscus_10k.ply", o).mesh;
  }();
  return m;
}

// A 2 mm punch centred on the meniscus' inner rim at angle psi (deg), from z0 up through the top (m).
TriMesh rim_punch(double psi_deg, double z0) {
  const double psi = psi_deg * std::numbers::pi / 180.0;
  return cylinder(0.01275 * std::cos(psi), 0.006 * std::sin(psi), 0.001, z0, 0.012);
}

TEST(SurfaceCut, PartialPunchIntoTheMeniscus) {
  const TriMesh& s = meniscus();
  const SurfaceCutResult r = cut_surface(s, rim_punch(270.0, 0.0005));
  expect_valid_cut(s, r, "meniscus");
  EXPECT_GT(r.removed_volume, 0.0);
  EXPECT_LT(r.removed_volume, prism_area(0.001, 32) * (0.012 - 0.0005));
  EXPECT_LT(r.patch_triangles, static_cast<int>(s.triangles.size()) / 10);
  EXPECT_FALSE(r.removed_vertices.empty());
  EXPECT_FALSE(r.inserted_vertices.empty());
}

TEST(SurfaceCut, SixPunchesIntoTheMeniscus) {
  TriMesh s = meniscus();
  const double v0 = sim::signed_volume(s);
  double removed = 0.0;
  for (int i = 0; i < 6; ++i) {
    const SurfaceCutResult r = cut_surface(s, rim_punch(150.0 + 45.0 * i, 0.0001 * i));
    expect_valid_cut(s, r, "punch " + std::to_string(i));
    removed += r.removed_volume;
    s = r.mesh;
  }
  EXPECT_NEAR(v0 - sim::signed_volume(s), removed, 1e-10 * v0);
  EXPECT_GT(removed, 0.0);
}

}  // namespace
}  // namespace octocut::cutting
